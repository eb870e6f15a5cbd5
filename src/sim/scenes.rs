//! Ready-made [`World`]s: an urban loop, a featureless corridor, an infinite floor and small
//! ground test scenes with labelled objects at known gaps.
//!
//! All scenes are in a world frame with z up and the ground (where flat) at z = 0; a vehicle
//! carries its sensor [`SENSOR_HEIGHT_M`] above the ground (the trajectories of
//! [`super::motion`] do). Ground surfaces are labelled [`GROUND`](super::scene::GROUND) by slope
//! (≤ 15°); every other surface carries its object's id. Object ids are unique per scene.
//!
//! | name | content |
//! |------|---------|
//! | `urban` | a 150 × 100 m block of streets (a ≈ 483 m loop; [`super::motion::Route::urban`] drives it once and 60 m on) with kerbs, sidewalks, building walls at irregular setbacks on both sides, parked cars (boxes) and poles |
//! | `corridor` | two parallel infinite walls (y = ±2.5 m), floor (z = 0) and ceiling (z = 3 m): no feature along x |
//! | `flat_floor` | the infinite plane z = 0 only |
//! | `flat`, `slope10`, `ramp`, `kerbs` | ground test scenes, see [`ground_scene`] |
//!
//! ```
//! use ringscan::sim::scenes;
//! use ringscan::sim::scene::{Scene, GROUND};
//! let w = scenes::named("kerbs").unwrap();
//! // Straight down from the sensor: the road.
//! let h = w.cast([0.0, 0.0, 1.8], [0.0, 0.0, -1.0]).unwrap();
//! assert_eq!(h.label, GROUND);
//! ```

use super::scene::{Object, Prim, World};

/// Height of the sensor above the ground the trajectories use, metres.
pub const SENSOR_HEIGHT_M: f64 = 1.8;
/// Maximum range of the ready-made scenes, metres.
pub const MAX_RANGE_M: f64 = 120.0;

/// Names accepted by [`named`].
pub const NAMES: [&str; 7] = [
    "urban",
    "corridor",
    "flat_floor",
    "flat",
    "slope10",
    "ramp",
    "kerbs",
];

/// The scene of a name in [`NAMES`].
pub fn named(name: &str) -> Option<World> {
    Some(match name {
        "urban" => urban(),
        "corridor" => corridor(),
        "flat_floor" => flat_floor(),
        "flat" | "slope10" | "ramp" | "kerbs" => ground_scene(name)?,
        _ => return None,
    })
}

/// Assigns ids in order of insertion (from 2; id 1 is the ground plane's).
struct Builder {
    objects: Vec<Object>,
    next: u32,
}

impl Builder {
    fn new() -> Self {
        Self {
            objects: Vec::new(),
            next: 2,
        }
    }

    fn ground(&mut self, p: Prim) -> u32 {
        self.push(Object::ground(p))
    }

    fn object(&mut self, p: Prim) -> u32 {
        self.push(Object::new(0, p))
    }

    fn push(&mut self, o: Object) -> u32 {
        let id = if matches!(o.prim, Prim::Plane { .. }) && o.ground_by_slope {
            1
        } else {
            let id = self.next;
            self.next += 1;
            id
        };
        let r = if o.ground_by_slope {
            o.reflectivity
        } else {
            Object::new(id, o.prim).reflectivity
        };
        self.objects.push(o.with_id(id).with_reflectivity(r));
        id
    }

    fn build(self) -> World {
        World::new(self.objects, MAX_RANGE_M)
    }
}

fn floor(z: f64) -> Prim {
    Prim::Plane {
        normal: [0.0, 0.0, 1.0],
        d: z,
    }
}

/// Axis-aligned box from corner ranges.
fn aabb(x: [f64; 2], y: [f64; 2], z: [f64; 2]) -> Prim {
    Prim::Box {
        center: [0.5 * (x[0] + x[1]), 0.5 * (y[0] + y[1])],
        half: [0.5 * (x[1] - x[0]), 0.5 * (y[1] - y[0])],
        yaw: 0.0,
        z0: z[0],
        z1: z[1],
    }
}

/// A deterministic pseudo-random sequence in [0, 1) (xorshift64*), so scenes need no RNG crate.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// The urban loop: the centreline of its streets is the rectangle [0, 150] × [0, 100] m with
/// corners rounded to 10 m ([`super::motion::Route::urban`] drives it counter-clockwise from
/// (20, 0), once around and on to (80, 0)). Roads are 10 m wide (kerbs 5 m from the centreline, 15 cm high); sidewalks 7 m
/// wide on the outside, the whole inner block raised as sidewalk; building walls (boxes 6–20 m
/// high, irregular lengths, setbacks and gaps) on both sides; parked cars on straight stretches
/// 3.9 m from the centreline (clear of the corners); poles 1 m behind the kerbs at irregular
/// spacing. Nothing stands on the roads' centrelines or the route's corner arcs: a vehicle
/// driving [`super::motion::Route::urban`] is clear of every object. Sidewalk tops are at
/// z = 0.15 m, everything else on the ground at z = 0.
pub fn urban() -> World {
    let mut b = Builder::new();
    let mut rng = Lcg(0x9E37_79B9_7F4A_7C15);
    b.ground(floor(0.0));
    let kerb = 0.15;
    // Inner block and outer sidewalks (ground on top, kerb faces are objects).
    b.ground(aabb([5.0, 145.0], [5.0, 95.0], [0.0, kerb]));
    b.ground(aabb([-12.0, 162.0], [-12.0, -5.0], [0.0, kerb]));
    b.ground(aabb([-12.0, 162.0], [105.0, 112.0], [0.0, kerb]));
    b.ground(aabb([-12.0, -5.0], [-5.0, 105.0], [0.0, kerb]));
    b.ground(aabb([155.0, 162.0], [-5.0, 105.0], [0.0, kerb]));
    // Streets as (start, end) of the centreline, with the inner side on the left.
    let streets: [([f64; 2], [f64; 2]); 4] = [
        ([0.0, 0.0], [150.0, 0.0]),
        ([150.0, 0.0], [150.0, 100.0]),
        ([150.0, 100.0], [0.0, 100.0]),
        ([0.0, 100.0], [0.0, 0.0]),
    ];
    for (a, e) in streets {
        let len = ((e[0] - a[0]).powi(2) + (e[1] - a[1]).powi(2)).sqrt();
        let t = [(e[0] - a[0]) / len, (e[1] - a[1]) / len];
        let left = [-t[1], t[0]];
        let yaw = t[1].atan2(t[0]);
        let at = |s: f64, l: f64| [a[0] + s * t[0] + l * left[0], a[1] + s * t[1] + l * left[1]];
        for side in [1.0, -1.0] {
            // Inner side: on the block, clear of the cross streets (13 m from each end);
            // outer side: beyond the sidewalk, the whole length.
            let (lo, hi) = if side > 0.0 {
                (13.0, len - 13.0)
            } else {
                (0.0, len)
            };
            // Buildings: inner side 8.5–14 m from the centreline, outer side 12.5–16 m.
            let mut s = lo + rng.range(0.0, 8.0);
            while s < hi - 6.0 {
                let l = rng.range(8.0, 25.0).min(hi - s);
                let setback = if side > 0.0 {
                    rng.range(8.5, 14.0)
                } else {
                    rng.range(12.5, 16.0)
                };
                let depth = rng.range(3.0, 8.0);
                let c = at(s + 0.5 * l, side * (setback + 0.5 * depth));
                let base = kerb;
                b.object(Prim::Box {
                    center: c,
                    half: [0.5 * l, 0.5 * depth],
                    yaw,
                    z0: base - 0.5,
                    z1: base + rng.range(6.0, 20.0),
                });
                s += l + rng.range(2.0, 9.0);
            }
            // Parked cars on the road, away from the corners.
            let mut s = 16.0 + rng.range(0.0, 6.0);
            while s < len - 20.0 {
                if rng.next() < 0.6 {
                    let c = at(s, side * 3.9);
                    b.object(Prim::Box {
                        center: c,
                        half: [2.2, 0.9],
                        yaw: yaw + rng.range(-0.05, 0.05),
                        z0: -0.1,
                        z1: rng.range(1.4, 1.9),
                    });
                }
                s += rng.range(6.0, 14.0);
            }
            // Poles on the sidewalks, 1 m behind the kerb.
            let mut s = lo + rng.range(3.0, 15.0);
            while s < hi {
                let c = at(s, side * 6.0);
                b.object(Prim::Cylinder {
                    center: c,
                    radius: rng.range(0.1, 0.2),
                    z0: 0.0,
                    z1: rng.range(4.0, 8.0),
                });
                s += rng.range(10.0, 28.0);
            }
        }
    }
    b.build()
}

/// A corridor along x: walls y = ±2.5 m, floor z = 0, ceiling z = 3 m, all infinite.
pub fn corridor() -> World {
    let mut b = Builder::new();
    b.ground(floor(0.0));
    for (n, d) in [([0.0, 1.0, 0.0], 2.5), ([0.0, -1.0, 0.0], 2.5)] {
        b.object(Prim::Plane { normal: n, d });
    }
    b.object(Prim::Plane {
        normal: [0.0, 0.0, 1.0],
        d: 3.0,
    });
    b.build()
}

/// The infinite plane z = 0, nothing else.
pub fn flat_floor() -> World {
    let mut b = Builder::new();
    b.ground(floor(0.0));
    b.build()
}

/// Ground test scenes around a sensor at (0, 0, 1.8) m; `name`: `flat` (z = 0), `slope10`
/// (z = 0.1·x, a 10 % slope rising along +x), `ramp` (z = 0 up to x = 6 m, a 15 % ramp to
/// z = 1.5 m at x = 16 m, a plateau up to x = 60 m, |y| ≤ 30 m, the plateau's sides are
/// objects), `kerbs` (road z = 0, sidewalks 15 cm high for 4 ≤ |y| ≤ 9 m and a 12 cm step
/// across the road at x = 15 m: kerb tops and road are ground, kerb faces are not).
///
/// Each stands the same objects on its ground (`h(x, y)` the ground height, bases buried
/// 0.3 m so no gap shows):
/// - box A: x ∈ [7.5, 8.5], y ∈ [−1.5, −0.5], 1.5 m high; box B: x ∈ [7.5, 8.5],
///   y ∈ [0.3, 1.3], 1.0 m high — a 0.8 m gap between A and B;
/// - pole P: axis (12, 3), radius 0.15, 4 m high; box C: x ∈ [11.6, 12.4], y ∈ [3.6, 4.4],
///   1.2 m high — a 0.45 m gap between P and C;
/// - sphere S: radius 0.5 resting on the ground at (−6, 2); a car-sized box D at (−8, −4),
///   4.4 × 1.8 × 1.5 m, yaw 30°;
/// - on `kerbs` box A and B stand on the road (clear of the step), C and P on the sidewalk.
pub fn ground_scene(name: &str) -> Option<World> {
    let mut b = Builder::new();
    let h: fn(f64, f64) -> f64 = match name {
        "flat" => {
            b.ground(floor(0.0));
            |_, _| 0.0
        }
        "slope10" => {
            let n = 1.0 / (1.0f64 + 0.01).sqrt();
            b.ground(Prim::Plane {
                normal: [-0.1 * n, 0.0, n],
                d: 0.0,
            });
            |x, _| 0.1 * x
        }
        "ramp" => {
            b.ground(floor(0.0));
            b.ground(Prim::Patch {
                p0: [6.0, -30.0, 0.0],
                e1: [10.0, 0.0, 1.5],
                e2: [0.0, 60.0, 0.0],
            });
            b.ground(aabb([16.0, 60.0], [-30.0, 30.0], [-0.5, 1.5]));
            |x, y| {
                if y.abs() > 30.0 || !(6.0..=60.0).contains(&x) {
                    0.0
                } else if x < 16.0 {
                    0.15 * (x - 6.0)
                } else {
                    1.5
                }
            }
        }
        "kerbs" => {
            b.ground(floor(0.0));
            b.ground(aabb([-50.0, 50.0], [4.0, 9.0], [-0.5, 0.15]));
            b.ground(aabb([-50.0, 50.0], [-9.0, -4.0], [-0.5, 0.15]));
            b.ground(aabb([15.0, 50.0], [-4.0, 4.0], [-0.5, 0.12]));
            |x, y| {
                if (4.0..=9.0).contains(&y.abs()) && x.abs() <= 50.0 {
                    0.15
                } else if (15.0..=50.0).contains(&x) && y.abs() < 4.0 {
                    0.12
                } else {
                    0.0
                }
            }
        }
        _ => return None,
    };
    // Boxes stand on the ground at their centre, buried 0.3 m.
    let stand = |b: &mut Builder, x: [f64; 2], y: [f64; 2], height: f64| {
        let g = h(0.5 * (x[0] + x[1]), 0.5 * (y[0] + y[1]));
        b.object(aabb(x, y, [g - 0.3 - 0.1 * (x[1] - x[0]), g + height]));
    };
    stand(&mut b, [7.5, 8.5], [-1.5, -0.5], 1.5);
    stand(&mut b, [7.5, 8.5], [0.3, 1.3], 1.0);
    let gp = h(12.0, 3.0);
    b.object(Prim::Cylinder {
        center: [12.0, 3.0],
        radius: 0.15,
        z0: gp - 0.3,
        z1: gp + 4.0,
    });
    stand(&mut b, [11.6, 12.4], [3.6, 4.4], 1.2);
    b.object(Prim::Sphere {
        center: [-6.0, 2.0, h(-6.0, 2.0) + 0.5],
        radius: 0.5,
    });
    let gd = h(-8.0, -4.0);
    b.object(Prim::Box {
        center: [-8.0, -4.0],
        half: [2.2, 0.9],
        yaw: 30f64.to_radians(),
        z0: gd - 0.6,
        z1: gd + 1.5,
    });
    Some(b.build())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::scene::Scene;
    use crate::sim::scene::GROUND;

    #[test]
    fn kerb_tops_and_road_are_ground_kerb_faces_are_not() {
        let w = ground_scene("kerbs").unwrap();
        // Down onto the road and onto the sidewalk.
        let h = w.cast([0.0, 0.0, 1.8], [0.0, 0.0, -1.0]).unwrap();
        assert_eq!((h.label, h.range), (GROUND, 1.8));
        let h = w.cast([0.0, 6.0, 1.8], [0.0, 0.0, -1.0]).unwrap();
        assert_eq!(h.label, GROUND);
        assert!((h.range - 1.65).abs() < 1e-12);
        // Horizontally at 5 cm height into the kerb face at y = 4.
        let h = w.cast([-20.0, 0.0, 0.05], [0.0, 1.0, 0.0]).unwrap();
        assert_ne!(h.label, GROUND);
        assert!((h.range - 4.0).abs() < 1e-12);
        assert_eq!(h.normal, [0.0, -1.0, 0.0]);
    }

    #[test]
    fn slope_is_ground_and_objects_stand_on_it() {
        let w = ground_scene("slope10").unwrap();
        let h = w.cast([20.0, -10.0, 10.0], [0.0, 0.0, -1.0]).unwrap();
        assert_eq!(h.label, GROUND);
        assert!((h.range - 8.0).abs() < 1e-9);
        // Box A's top: ground height at its centre (0.8) + 1.5.
        let h = w.cast([8.0, -1.0, 10.0], [0.0, 0.0, -1.0]).unwrap();
        assert_ne!(h.label, GROUND);
        assert!((h.range - (10.0 - 2.3)).abs() < 1e-9);
    }

    #[test]
    fn the_urban_route_is_clear_of_every_object() {
        use crate::sim::motion::Route;
        use crate::sim::motion::Trajectory;
        let w = urban();
        let route = Route::urban();
        let dur = route.duration_s();
        let tr = Trajectory::route(0, route);
        // A vehicle 2 m wide: rays sideways and down from the sensor path at 0.5 m steps hit
        // nothing closer than 1 m sideways (kerb faces included) and the road straight below.
        let n = (dur * 30.0) as usize;
        for k in 0..=n {
            let p = tr.pose_s(dur * k as f64 / n as f64);
            let o: [f64; 3] = p.translation.vector.into();
            let down = w.cast(o, [0.0, 0.0, -1.0]).unwrap();
            assert_eq!(down.label, GROUND, "at {o:?}");
            assert!((down.range - 1.8).abs() < 1e-9, "road under {o:?}");
            for h in [0.1, 0.5, 1.0] {
                for a in 0..16 {
                    let az = f64::from(a) * std::f64::consts::PI / 8.0;
                    let d = [az.cos(), az.sin(), 0.0];
                    let lo = [o[0], o[1], h];
                    if let Some(hit) = w.cast(lo, d) {
                        assert!(
                            hit.range > 1.0,
                            "object {} {} m from {lo:?}",
                            hit.label,
                            hit.range
                        );
                    }
                }
            }
        }
    }
}
