//! A world of textured primitives, some of them marked as "the object to remove", and its
//! view-independent shading (Lambert with ambient, no shadows, so that removing the object
//! changes no pixel outside its projection).

use super::geometry::{add_scaled, dot, normalize, Geometry, Ray, V3};
use super::texture::{Rgb, Texture};

/// One textured primitive.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    /// Its geometry.
    pub geometry: Geometry,
    /// Its albedo texture.
    pub texture: Texture,
    /// Whether it belongs to the object to remove.
    pub object: bool,
}

/// A ray hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter (distance, since rays are unit).
    pub t: f64,
    /// World point.
    pub point: V3,
    /// Unit world normal, facing the ray.
    pub normal: V3,
    /// Index of the shape hit.
    pub shape: usize,
    /// Whether the shape belongs to the object.
    pub object: bool,
}

/// A scene for the tracer.
#[derive(Debug, Clone, PartialEq)]
pub struct World {
    /// All shapes.
    pub shapes: Vec<Shape>,
    /// Unit direction towards the light.
    pub light: V3,
    /// Ambient term.
    pub ambient: f64,
}

/// The nearest hits of a ray: among the background shapes and among the object shapes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplitHit {
    /// Nearest hit ignoring the object (the scene "without the object").
    pub background: Option<Hit>,
    /// Nearest hit on the object, if any.
    pub object: Option<Hit>,
}

impl SplitHit {
    /// The nearest hit of the full scene (with the object).
    pub fn with_object(&self) -> Option<Hit> {
        match (self.background, self.object) {
            (Some(b), Some(o)) => Some(if o.t < b.t { o } else { b }),
            (b, o) => o.or(b),
        }
    }

    /// Whether the object is the first thing this ray sees.
    pub fn sees_object(&self) -> bool {
        self.with_object().is_some_and(|h| h.object)
    }
}

impl World {
    /// A new world with the default light.
    pub fn new(shapes: Vec<Shape>) -> Self {
        Self {
            shapes,
            light: normalize([0.45, 0.8, 0.55]),
            ambient: 0.35,
        }
    }

    /// Traces a ray against every shape.
    pub fn trace(&self, ray: &Ray) -> SplitHit {
        let mut out = SplitHit {
            background: None,
            object: None,
        };
        for (i, s) in self.shapes.iter().enumerate() {
            if let Some((t, normal)) = s.geometry.intersect(ray) {
                let slot = if s.object {
                    &mut out.object
                } else {
                    &mut out.background
                };
                if slot.is_none_or(|h| t < h.t) {
                    *slot = Some(Hit {
                        t,
                        point: add_scaled(ray.origin, ray.dir, t),
                        normal,
                        shape: i,
                        object: s.object,
                    });
                }
            }
        }
        out
    }

    /// The shaded colour of a hit (view-independent).
    pub fn shade(&self, hit: &Hit) -> Rgb {
        let albedo = self.shapes[hit.shape].texture.albedo(hit.point);
        let k = self.ambient + (1.0 - self.ambient) * dot(hit.normal, self.light).max(0.0);
        [albedo[0] * k, albedo[1] * k, albedo[2] * k]
    }
}
