//! Ray-cast scenes with known geometry: the ground truth for encoders and the simulator.

/// Where a ray hits the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray, metres.
    pub range: f64,
    /// Reflectivity to report (0..=255).
    pub reflectivity: u8,
}

/// Something rays can be cast into.
pub trait Scene {
    /// First hit of the ray `origin + s·dir` (`dir` a unit vector, `s > 0`), if any.
    fn cast(&self, origin: [f64; 3], dir: [f64; 3]) -> Option<Hit>;
}

/// A plane `n·p = d` with a reflectivity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// Unit normal.
    pub normal: [f64; 3],
    /// Offset along the normal.
    pub d: f64,
    /// Reflectivity.
    pub reflectivity: u8,
}

/// A sphere with a reflectivity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Centre, metres.
    pub center: [f64; 3],
    /// Radius, metres.
    pub radius: f64,
    /// Reflectivity.
    pub reflectivity: u8,
}

/// A scene made of planes and spheres, with a maximum range.
#[derive(Clone, Debug, PartialEq)]
pub struct Shapes {
    /// Planes.
    pub planes: Vec<Plane>,
    /// Spheres.
    pub spheres: Vec<Sphere>,
    /// Rays travelling farther than this return nothing.
    pub max_range: f64,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Shapes {
    /// A rectangular room `[-x, x] × [-y, y]` with floor at `-floor` and ceiling at `ceiling`
    /// (sensor at the origin), plus a few spheres: a scene with every elevation hit.
    pub fn room(x: f64, y: f64, floor: f64, ceiling: f64) -> Self {
        let p = |n: [f64; 3], d: f64, r: u8| Plane {
            normal: n,
            d,
            reflectivity: r,
        };
        Self {
            planes: vec![
                p([1.0, 0.0, 0.0], x, 40),
                p([-1.0, 0.0, 0.0], x, 60),
                p([0.0, 1.0, 0.0], y, 80),
                p([0.0, -1.0, 0.0], y, 100),
                p([0.0, 0.0, -1.0], floor, 20),
                p([0.0, 0.0, 1.0], ceiling, 120),
            ],
            spheres: vec![
                Sphere {
                    center: [4.0, 1.0, 0.0],
                    radius: 0.8,
                    reflectivity: 200,
                },
                Sphere {
                    center: [-3.0, -2.5, -0.5],
                    radius: 0.5,
                    reflectivity: 255,
                },
            ],
            max_range: 120.0,
        }
    }
}

impl Scene for Shapes {
    fn cast(&self, o: [f64; 3], dir: [f64; 3]) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut take = |s: f64, r: u8| {
            if s > 1e-6 && s <= self.max_range && best.is_none_or(|b| s < b.range) {
                best = Some(Hit {
                    range: s,
                    reflectivity: r,
                });
            }
        };
        for pl in &self.planes {
            let den = dot(pl.normal, dir);
            if den.abs() > 1e-12 {
                take((pl.d - dot(pl.normal, o)) / den, pl.reflectivity);
            }
        }
        for sp in &self.spheres {
            let oc = [
                o[0] - sp.center[0],
                o[1] - sp.center[1],
                o[2] - sp.center[2],
            ];
            let b = dot(oc, dir);
            let c = dot(oc, oc) - sp.radius * sp.radius;
            let disc = b * b - c;
            if disc >= 0.0 {
                let r = disc.sqrt();
                take(-b - r, sp.reflectivity);
                take(-b + r, sp.reflectivity);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn casts_hit_the_nearest_surface() {
        let s = Shapes::room(10.0, 8.0, 2.0, 3.0);
        let h = s.cast([0.0; 3], [1.0, 0.0, 0.0]).unwrap();
        // The sphere at (4, 1, 0) r 0.8 is not on the x axis (distance 1 > 0.8): the wall at 10.
        assert!((h.range - 10.0).abs() < 1e-12);
        let h = s.cast([0.0; 3], [0.0, 0.0, -1.0]).unwrap();
        assert!((h.range - 2.0).abs() < 1e-12);
        // Straight at the sphere centre: 4.123 − 0.8.
        let c: [f64; 3] = [4.0, 1.0, 0.0];
        let n = (17f64).sqrt();
        let h = s.cast([0.0; 3], [c[0] / n, c[1] / n, 0.0]).unwrap();
        assert!((h.range - (n - 0.8)).abs() < 1e-9);
        assert_eq!(h.reflectivity, 200);
    }
}
