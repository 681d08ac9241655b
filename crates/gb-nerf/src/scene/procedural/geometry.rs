//! Analytic ray-primitive intersection in `f64`: planes, axis-aligned boxes, spheres and
//! vertical capped cylinders. Normals are unit, outward, and flipped to face the ray.
// Component loops over xyz / matrix entries read clearer with indices than with zips.
#![allow(clippy::needless_range_loop)]

/// A 3-vector.
pub type V3 = [f64; 3];

/// `a + s * b`.
pub fn add_scaled(a: V3, b: V3, s: f64) -> V3 {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

/// `a - b`.
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Dot product.
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product.
pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Unit vector (the input must be non-zero).
pub fn normalize(a: V3) -> V3 {
    let n = dot(a, a).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}

/// A ray `origin + t * dir`, `dir` unit.
#[derive(Debug, Clone, Copy)]
pub struct Ray {
    /// Origin.
    pub origin: V3,
    /// Unit direction.
    pub dir: V3,
}

/// A geometric primitive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Geometry {
    /// The infinite plane `normal . x = offset` (two-sided).
    Plane {
        /// Unit normal.
        normal: V3,
        /// Offset along the normal.
        offset: f64,
    },
    /// An axis-aligned box.
    Cuboid {
        /// Minimum corner.
        min: V3,
        /// Maximum corner.
        max: V3,
    },
    /// A sphere.
    Sphere {
        /// Centre.
        center: V3,
        /// Radius.
        radius: f64,
    },
    /// A capped cylinder with a vertical (y) axis.
    Cylinder {
        /// x of the axis.
        x: f64,
        /// z of the axis.
        z: f64,
        /// Radius.
        radius: f64,
        /// Bottom.
        y0: f64,
        /// Top.
        y1: f64,
    },
}

/// Rays closer than this do not count as hits.
pub const T_MIN: f64 = 1e-6;

impl Geometry {
    /// The nearest hit `(t, unit normal facing the ray)` with `t > T_MIN`.
    pub fn intersect(&self, ray: &Ray) -> Option<(f64, V3)> {
        let hit = match *self {
            Geometry::Plane { normal, offset } => {
                let den = dot(normal, ray.dir);
                if den.abs() < 1e-12 {
                    return None;
                }
                let t = (offset - dot(normal, ray.origin)) / den;
                (t > T_MIN).then_some((t, normal))
            }
            Geometry::Cuboid { min, max } => cuboid(ray, min, max),
            Geometry::Sphere { center, radius } => {
                let oc = sub(ray.origin, center);
                let b = dot(oc, ray.dir);
                let c = dot(oc, oc) - radius * radius;
                let disc = b * b - c;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                let t = if -b - s > T_MIN { -b - s } else { -b + s };
                if t <= T_MIN {
                    return None;
                }
                let p = add_scaled(ray.origin, ray.dir, t);
                Some((t, normalize(sub(p, center))))
            }
            Geometry::Cylinder {
                x,
                z,
                radius,
                y0,
                y1,
            } => cylinder(ray, x, z, radius, y0, y1),
        }?;
        let n = if dot(hit.1, ray.dir) > 0.0 {
            [-hit.1[0], -hit.1[1], -hit.1[2]]
        } else {
            hit.1
        };
        Some((hit.0, n))
    }
}

fn cuboid(ray: &Ray, min: V3, max: V3) -> Option<(f64, V3)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    let (mut axis0, mut axis1) = (0usize, 0usize);
    for a in 0..3 {
        if ray.dir[a].abs() < 1e-15 {
            if ray.origin[a] < min[a] || ray.origin[a] > max[a] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / ray.dir[a];
        let (mut ta, mut tb) = (
            (min[a] - ray.origin[a]) * inv,
            (max[a] - ray.origin[a]) * inv,
        );
        if ta > tb {
            std::mem::swap(&mut ta, &mut tb);
        }
        if ta > t0 {
            t0 = ta;
            axis0 = a;
        }
        if tb < t1 {
            t1 = tb;
            axis1 = a;
        }
    }
    if t0 > t1 {
        return None;
    }
    let (t, axis) = if t0 > T_MIN {
        (t0, axis0)
    } else if t1 > T_MIN {
        (t1, axis1)
    } else {
        return None;
    };
    let mut n = [0.0; 3];
    n[axis] = -ray.dir[axis].signum();
    Some((t, n))
}

fn cylinder(ray: &Ray, cx: f64, cz: f64, r: f64, y0: f64, y1: f64) -> Option<(f64, V3)> {
    let mut best: Option<(f64, V3)> = None;
    let mut consider = |t: f64, n: V3| {
        if t > T_MIN && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, n));
        }
    };
    // side: (ox + t dx - cx)^2 + (oz + t dz - cz)^2 = r^2
    let (ox, oz) = (ray.origin[0] - cx, ray.origin[2] - cz);
    let (dx, dz) = (ray.dir[0], ray.dir[2]);
    let a = dx * dx + dz * dz;
    if a > 1e-15 {
        let b = ox * dx + oz * dz;
        let c = ox * ox + oz * oz - r * r;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let s = disc.sqrt();
            for t in [(-b - s) / a, (-b + s) / a] {
                let y = ray.origin[1] + t * ray.dir[1];
                if y >= y0 && y <= y1 {
                    let px = ox + t * dx;
                    let pz = oz + t * dz;
                    consider(t, [px / r, 0.0, pz / r]);
                }
            }
        }
    }
    // caps
    if ray.dir[1].abs() > 1e-15 {
        for (yc, ny) in [(y0, -1.0), (y1, 1.0)] {
            let t = (yc - ray.origin[1]) / ray.dir[1];
            let px = ox + t * dx;
            let pz = oz + t * dz;
            if px * px + pz * pz <= r * r {
                consider(t, [0.0, ny, 0.0]);
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: V3, d: V3) -> Ray {
        Ray {
            origin: o,
            dir: normalize(d),
        }
    }

    #[test]
    fn closed_forms() {
        let r = ray([0.0, 0.0, 5.0], [0.0, 0.0, -1.0]);
        let s = Geometry::Sphere {
            center: [0.0; 3],
            radius: 1.0,
        }
        .intersect(&r)
        .unwrap();
        assert!((s.0 - 4.0).abs() < 1e-12 && s.1 == [0.0, 0.0, 1.0]);
        let b = Geometry::Cuboid {
            min: [-1.0; 3],
            max: [1.0, 1.0, 2.0],
        }
        .intersect(&r)
        .unwrap();
        assert!((b.0 - 3.0).abs() < 1e-12 && b.1 == [0.0, 0.0, 1.0]);
        let p = Geometry::Plane {
            normal: [0.0, 0.0, 1.0],
            offset: -2.0,
        }
        .intersect(&r)
        .unwrap();
        assert!((p.0 - 7.0).abs() < 1e-12);
        let c = Geometry::Cylinder {
            x: 0.0,
            z: 0.0,
            radius: 0.5,
            y0: -1.0,
            y1: 1.0,
        }
        .intersect(&r)
        .unwrap();
        assert!((c.0 - 4.5).abs() < 1e-12 && (c.1[2] - 1.0).abs() < 1e-12);
        // from above onto the cap
        let down = ray([0.1, 5.0, 0.0], [0.0, -1.0, 0.0]);
        let c = Geometry::Cylinder {
            x: 0.0,
            z: 0.0,
            radius: 0.5,
            y0: -1.0,
            y1: 1.0,
        }
        .intersect(&down)
        .unwrap();
        assert!((c.0 - 4.0).abs() < 1e-12 && c.1 == [0.0, 1.0, 0.0]);
        // a miss
        let miss = ray([3.0, 0.0, 5.0], [0.0, 0.0, -1.0]);
        assert!(Geometry::Sphere {
            center: [0.0; 3],
            radius: 1.0
        }
        .intersect(&miss)
        .is_none());
    }

    #[test]
    fn plane_normal_faces_the_ray() {
        let r = ray([0.0, 1.0, 0.0], [0.0, -1.0, 0.2]);
        let (_, n) = Geometry::Plane {
            normal: [0.0, -1.0, 0.0],
            offset: 0.0,
        }
        .intersect(&r)
        .unwrap();
        assert_eq!(n, [0.0, 1.0, 0.0]);
    }
}
