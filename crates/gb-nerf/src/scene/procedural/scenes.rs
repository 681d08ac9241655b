//! The built-in scenes: `stairs` (a textured staircase with an object standing on a step),
//! `fence` (a periodic picket fence in front of a brick wall, with an object in front) and
//! `alcove` (an object standing in a recess of a wall, so that most of what it hides, the
//! recess's tiled back, is seen by no view) and `wall` (an object standing in front of a flat
//! brick wall: the hidden surface is one plane, partly seen by the other views).
//! World axes: y up; the cameras look roughly along -z. Units: metres, loosely.

use super::geometry::{Geometry, V3};
use super::texture::{Rgb, Texture};
use super::world::{Shape, World};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Which built-in scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SceneName {
    /// A textured staircase with an object (a vase) standing on a step.
    Stairs,
    /// A periodic fence in front of a wall, with an object (a ball on a crate) in front.
    Fence,
    /// A plastered wall with a recess, an object (a vase) standing in it.
    Alcove,
    /// A flat brick wall with an object (a vase) standing in front of it.
    Wall,
}

impl SceneName {
    /// Every scene.
    pub const ALL: [SceneName; 4] = [
        SceneName::Stairs,
        SceneName::Fence,
        SceneName::Alcove,
        SceneName::Wall,
    ];

    /// Its command-line name.
    pub fn as_str(&self) -> &'static str {
        match self {
            SceneName::Stairs => "stairs",
            SceneName::Fence => "fence",
            SceneName::Alcove => "alcove",
            SceneName::Wall => "wall",
        }
    }
}

impl std::fmt::Display for SceneName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for SceneName {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "stairs" => Ok(SceneName::Stairs),
            "fence" => Ok(SceneName::Fence),
            "alcove" => Ok(SceneName::Alcove),
            "wall" => Ok(SceneName::Wall),
            other => Err(format!(
                "unknown procedural scene '{other}' (expected stairs, fence, alcove or wall)"
            )),
        }
    }
}

/// How the cameras move: a forward-facing arc around a target point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rig {
    /// The point the cameras look at.
    pub target: V3,
    /// Distance from the target.
    pub radius: f64,
    /// Azimuth range in degrees (0 = looking along -z).
    pub azimuth_deg: (f64, f64),
    /// Mean elevation in degrees (positive = looking down).
    pub elevation_deg: f64,
    /// Horizontal field of view in degrees.
    pub hfov_deg: f64,
}

/// A built scene: the world, the camera rig and captions.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSpec {
    /// Shapes and light.
    pub world: World,
    /// Camera arc.
    pub rig: Rig,
    /// Caption of a view with the object.
    pub caption_with_object: String,
    /// Caption of a view without the object.
    pub caption_without_object: String,
}

const PALETTE: [(&str, Rgb); 6] = [
    ("red", [0.82, 0.14, 0.12]),
    ("blue", [0.16, 0.32, 0.86]),
    ("yellow", [0.92, 0.80, 0.14]),
    ("green", [0.18, 0.68, 0.24]),
    ("purple", [0.56, 0.22, 0.72]),
    ("orange", [0.95, 0.50, 0.10]),
];

fn shape(geometry: Geometry, texture: Texture) -> Shape {
    Shape {
        geometry,
        texture,
        object: false,
    }
}

/// The object of `stairs` and `alcove`: a noise-textured cylinder (`body`: radius, height)
/// standing at `base` (x, y, z), topped by a checkered sphere (`head`: centre height above
/// the base, radius), both in `color`.
fn vase(
    rng: &mut ChaCha8Rng,
    s32: &impl Fn(&mut ChaCha8Rng) -> u32,
    color: Rgb,
    [x, y, z]: V3,
    (radius, height): (f64, f64),
    (head_y, head_radius): (f64, f64),
) -> [Shape; 2] {
    let body = Texture::Noise {
        a: color,
        b: jitter(rng, color, 0.15),
        freq: 9.0,
        seed: s32(rng),
    };
    [
        Shape {
            geometry: Geometry::Cylinder {
                x,
                z,
                radius,
                y0: y,
                y1: y + height,
            },
            texture: body,
            object: true,
        },
        Shape {
            geometry: Geometry::Sphere {
                center: [x, y + head_y, z],
                radius: head_radius,
            },
            texture: Texture::Checker {
                a: color,
                b: [0.95, 0.95, 0.92],
                cell: 0.08,
            },
            object: true,
        },
    ]
}

/// A palette colour drawn until its name differs from `other` (the object's against the
/// surface it hides).
fn colour_other_than(rng: &mut ChaCha8Rng, other: &str) -> (&'static str, Rgb) {
    loop {
        let c = PALETTE[rng.random_range(0..PALETTE.len())];
        if c.0 != other {
            return c;
        }
    }
}

fn jitter(rng: &mut ChaCha8Rng, c: Rgb, amount: f64) -> Rgb {
    let mut out = c;
    for v in &mut out {
        *v = (*v + rng.random_range(-amount..amount)).clamp(0.0, 1.0);
    }
    out
}

/// Builds a scene for a seed.
pub fn build(name: SceneName, seed: u64) -> SceneSpec {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6762_6e65_7266_0000);
    let s32 = |rng: &mut ChaCha8Rng| rng.random::<u32>();
    match name {
        SceneName::Stairs => stairs(&mut rng, s32),
        SceneName::Fence => fence(&mut rng, s32),
        SceneName::Alcove => alcove(&mut rng, s32),
        SceneName::Wall => wall(&mut rng, s32),
    }
}

fn stairs(rng: &mut ChaCha8Rng, s32: impl Fn(&mut ChaCha8Rng) -> u32) -> SceneSpec {
    let mut shapes = vec![
        shape(
            Geometry::Plane {
                normal: [0.0, 1.0, 0.0],
                offset: 0.0,
            },
            Texture::Checker {
                a: jitter(rng, [0.72, 0.70, 0.66], 0.05),
                b: jitter(rng, [0.35, 0.33, 0.31], 0.05),
                cell: 0.5,
            },
        ),
        shape(
            Geometry::Plane {
                normal: [0.0, 0.0, 1.0],
                offset: -3.0,
            },
            Texture::Bricks {
                brick: jitter(rng, [0.62, 0.30, 0.22], 0.05),
                mortar: [0.80, 0.78, 0.74],
                width: 0.5,
                height: 0.2,
                seed: s32(rng),
            },
        ),
    ];
    let (steps, rise, run, z0) = (5usize, 0.25, 0.5, 1.0);
    let wood_dark = jitter(rng, [0.45, 0.28, 0.14], 0.04);
    let wood_light = jitter(rng, [0.78, 0.58, 0.36], 0.04);
    let grain_seed = s32(rng);
    for i in 0..steps {
        shapes.push(shape(
            Geometry::Cuboid {
                min: [-1.6, 0.0, z0 - (i + 1) as f64 * run],
                max: [1.6, (i + 1) as f64 * rise, z0 - i as f64 * run],
            },
            Texture::Grain {
                a: wood_dark,
                b: wood_light,
                freq: 6.0,
                seed: grain_seed,
            },
        ));
    }
    // the object: a vase (cylinder + sphere) standing on step 2 (top y = 0.75, z in [-0.5, 0])
    let (cname, color) = PALETTE[rng.random_range(0..PALETTE.len())];
    let x = rng.random_range(-0.35..0.35);
    let z = -0.25 + rng.random_range(-0.05..0.05);
    let top = 3.0 * rise;
    shapes.extend(vase(
        rng,
        &s32,
        color,
        [x, top, z],
        (0.2, 0.45),
        (0.62, 0.2),
    ));
    SceneSpec {
        world: World::new(shapes),
        rig: Rig {
            target: [0.0, 0.75, -0.4],
            radius: 4.2,
            azimuth_deg: (-18.0, 18.0),
            elevation_deg: 18.0,
            hfov_deg: 50.0,
        },
        caption_with_object: format!(
            "a wooden staircase in front of a brick wall, with a {cname} vase standing on a step"
        ),
        caption_without_object: "a wooden staircase in front of a brick wall".into(),
    }
}

fn fence(rng: &mut ChaCha8Rng, s32: impl Fn(&mut ChaCha8Rng) -> u32) -> SceneSpec {
    let mut shapes = vec![
        shape(
            Geometry::Plane {
                normal: [0.0, 1.0, 0.0],
                offset: 0.0,
            },
            Texture::Noise {
                a: jitter(rng, [0.20, 0.42, 0.14], 0.04),
                b: jitter(rng, [0.42, 0.62, 0.24], 0.04),
                freq: 3.0,
                seed: s32(rng),
            },
        ),
        shape(
            Geometry::Plane {
                normal: [0.0, 0.0, 1.0],
                offset: -4.0,
            },
            Texture::Bricks {
                brick: jitter(rng, [0.58, 0.34, 0.26], 0.05),
                mortar: [0.78, 0.76, 0.72],
                width: 0.45,
                height: 0.18,
                seed: s32(rng),
            },
        ),
    ];
    let paint = jitter(rng, [0.93, 0.93, 0.90], 0.03);
    let paint_dark = [paint[0] * 0.85, paint[1] * 0.85, paint[2] * 0.85];
    let fence_tex = Texture::Noise {
        a: paint,
        b: paint_dark,
        freq: 5.0,
        seed: s32(rng),
    };
    let (zf, pitch, slat) = (-2.0, 0.3, 0.11);
    let phase = rng.random_range(0.0..pitch);
    let mut x = -4.0 + phase;
    while x < 4.0 {
        shapes.push(shape(
            Geometry::Cuboid {
                min: [x, 0.0, zf - 0.03],
                max: [x + slat, 1.6, zf + 0.03],
            },
            fence_tex,
        ));
        x += pitch;
    }
    for y in [0.45, 1.25] {
        shapes.push(shape(
            Geometry::Cuboid {
                min: [-4.0, y, zf - 0.09],
                max: [4.0, y + 0.1, zf - 0.03],
            },
            fence_tex,
        ));
    }
    // the object: a ball on a crate, in front of the fence
    let (cname, color) = PALETTE[rng.random_range(0..PALETTE.len())];
    let cx = rng.random_range(-0.4..0.4);
    let cz = -0.9 + rng.random_range(-0.1..0.1);
    let crate_tex = Texture::Grain {
        a: [0.40, 0.26, 0.12],
        b: [0.70, 0.52, 0.30],
        freq: 8.0,
        seed: s32(rng),
    };
    shapes.push(Shape {
        geometry: Geometry::Cuboid {
            min: [cx - 0.3, 0.0, cz - 0.3],
            max: [cx + 0.3, 0.5, cz + 0.3],
        },
        texture: crate_tex,
        object: true,
    });
    shapes.push(Shape {
        geometry: Geometry::Sphere {
            center: [cx, 0.8, cz],
            radius: 0.3,
        },
        texture: Texture::Noise {
            a: color,
            b: jitter(rng, color, 0.2),
            freq: 7.0,
            seed: s32(rng),
        },
        object: true,
    });
    SceneSpec {
        world: World::new(shapes),
        rig: Rig { target: [0.0, 0.7, -1.6], radius: 4.0, azimuth_deg: (-15.0, 15.0), elevation_deg: 8.0, hfov_deg: 55.0 },
        caption_with_object: format!("a white picket fence in front of a brick wall on a lawn, with a {cname} ball on a wooden crate in front"),
        caption_without_object: "a white picket fence in front of a brick wall on a lawn".into(),
    }
}

fn alcove(rng: &mut ChaCha8Rng, s32: impl Fn(&mut ChaCha8Rng) -> u32) -> SceneSpec {
    let floor = shape(
        Geometry::Plane {
            normal: [0.0, 1.0, 0.0],
            offset: 0.0,
        },
        Texture::Checker {
            a: jitter(rng, [0.62, 0.56, 0.48], 0.05),
            b: jitter(rng, [0.40, 0.36, 0.30], 0.05),
            cell: 0.4,
        },
    );
    let plaster = Texture::Noise {
        a: jitter(rng, [0.86, 0.82, 0.72], 0.04),
        b: jitter(rng, [0.74, 0.70, 0.60], 0.04),
        freq: 4.0,
        seed: s32(rng),
    };
    // the wall's face at z = -2, the recess (x in [-w, w], y in [sill, lintel]) `depth` deep;
    // the wall is built of four blocks around the opening, whose inner faces are the
    // recess's sides, floor and ceiling
    let (zw, depth) = (-2.0, 0.7);
    let w = rng.random_range(0.55..0.7);
    let (sill, lintel) = (0.5, 1.6);
    let zb = zw - depth;
    let block = |min: V3, max: V3| shape(Geometry::Cuboid { min, max }, plaster);
    let mut shapes = vec![
        floor,
        block([-5.0, 0.0, zb], [-w, 3.5, zw]),
        block([w, 0.0, zb], [5.0, 3.5, zw]),
        block([-w, lintel, zb], [w, 3.5, zw]),
        block([-w, 0.0, zb], [w, sill, zw]),
    ];
    // the recess's back: coloured tiles, the surface the object hides
    let (tname, tile) = PALETTE[rng.random_range(0..PALETTE.len())];
    shapes.push(shape(
        Geometry::Cuboid {
            min: [-w, sill, zb - 0.1],
            max: [w, lintel, zb],
        },
        Texture::Bricks {
            brick: jitter(rng, tile, 0.08),
            mortar: [0.90, 0.89, 0.85],
            width: 0.2,
            height: 0.2,
            seed: s32(rng),
        },
    ));
    // the object: a vase standing on the recess's floor, in front of its back
    let (cname, color) = colour_other_than(rng, tname);
    let x = rng.random_range(-0.08..0.08);
    let z = zb + 0.35;
    shapes.extend(vase(
        rng,
        &s32,
        color,
        [x, sill, z],
        (0.26, 0.6),
        (0.76, 0.24),
    ));
    SceneSpec {
        world: World::new(shapes),
        rig: Rig {
            target: [0.0, 1.05, zw - 0.3],
            radius: 3.6,
            azimuth_deg: (-16.0, 16.0),
            elevation_deg: 10.0,
            hfov_deg: 48.0,
        },
        caption_with_object: format!(
            "a plastered wall with a recess tiled in {tname}, with a {cname} vase standing in it"
        ),
        caption_without_object: format!("a plastered wall with a recess tiled in {tname}"),
    }
}

/// A flat brick wall at z = -2 over a checkered floor, a vase standing 0.8 in front of it: the
/// smallest scene whose hidden surface has a known shape (one plane), for the geometry of a fill.
fn wall(rng: &mut ChaCha8Rng, s32: impl Fn(&mut ChaCha8Rng) -> u32) -> SceneSpec {
    let zw = -2.0;
    let floor = shape(
        Geometry::Plane {
            normal: [0.0, 1.0, 0.0],
            offset: 0.0,
        },
        Texture::Checker {
            a: jitter(rng, [0.66, 0.62, 0.56], 0.05),
            b: jitter(rng, [0.38, 0.35, 0.31], 0.05),
            cell: 0.4,
        },
    );
    let (bname, brick) = PALETTE[rng.random_range(0..PALETTE.len())];
    let bricks = shape(
        Geometry::Plane {
            normal: [0.0, 0.0, 1.0],
            offset: zw,
        },
        Texture::Bricks {
            brick: jitter(rng, brick, 0.08),
            mortar: [0.88, 0.86, 0.82],
            width: 0.3,
            height: 0.15,
            seed: s32(rng),
        },
    );
    let (cname, color) = colour_other_than(rng, bname);
    let mut shapes = vec![floor, bricks];
    let x = rng.random_range(-0.1..0.1);
    shapes.extend(vase(
        rng,
        &s32,
        color,
        [x, 0.0, zw + 0.8],
        (0.26, 0.7),
        (0.86, 0.24),
    ));
    SceneSpec {
        world: World::new(shapes),
        rig: Rig {
            target: [0.0, 0.6, zw + 0.4],
            radius: 3.4,
            azimuth_deg: (-18.0, 18.0),
            elevation_deg: 12.0,
            hfov_deg: 48.0,
        },
        caption_with_object: format!(
            "a {bname} brick wall with a {cname} vase standing in front of it"
        ),
        caption_without_object: format!("a {bname} brick wall"),
    }
}
