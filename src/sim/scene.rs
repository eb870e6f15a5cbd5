//! Ray-cast scenes with known geometry: the ground truth for encoders and the simulator.
//!
//! Every [`Hit`] carries a label and the surface normal. Labels: [`GROUND`] (0) is ground,
//! any other value is the id of the object hit (≥ 1). Surfaces of the ground primitives
//! ([`Object::ground_by_slope`]) are ground where their slope is at most 15°
//! ([`GROUND_MAX_SLOPE_DEG`]) and carry their object id elsewhere: a kerb's top and the road are
//! ground, the kerb's vertical face is not.
//!
//! Two scene types: [`Shapes`] (infinite planes and spheres, the sensor-centred room of the
//! encoder tests) and [`World`] (bounded primitives — ground patches, planes, yaw-oriented
//! boxes, vertical cylinders, spheres — culled by a 2-D uniform grid walked along the ray, fast
//! enough for long drives). Ready-made worlds are in [`super::scenes`].
//!
//! ```
//! use ringscan::sim::scene::{Object, Prim, Scene, World, GROUND};
//! let floor = Object::ground(Prim::Plane { normal: [0.0, 0.0, 1.0], d: 0.0 });
//! let pole = Object::new(7, Prim::Cylinder { center: [5.0, 0.0], radius: 0.2, z0: 0.0, z1: 4.0 });
//! let w = World::new(vec![floor, pole], 100.0);
//! let down = w.cast([0.0, 0.0, 1.8], [0.0, 0.0, -1.0]).unwrap();
//! assert_eq!((down.label, down.range), (GROUND, 1.8));
//! let ahead = w.cast([0.0, 0.0, 1.8], [1.0, 0.0, 0.0]).unwrap();
//! assert_eq!(ahead.label, 7);
//! assert!((ahead.range - 4.8).abs() < 1e-12 && (ahead.normal[0] + 1.0).abs() < 1e-12);
//! ```

/// The label of ground surfaces.
pub const GROUND: u32 = 0;
/// Steepest ground surface, degrees from horizontal.
pub const GROUND_MAX_SLOPE_DEG: f64 = 15.0;

/// Where a ray hits the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray, metres.
    pub range: f64,
    /// Reflectivity to report (0..=255).
    pub reflectivity: u8,
    /// [`GROUND`] (0) or the id of the object hit (≥ 1).
    pub label: u32,
    /// Unit surface normal at the hit, facing the ray (`normal · dir ≤ 0`), in the frame the ray
    /// was given in.
    pub normal: [f64; 3],
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
        // Labels: plane i is object i + 1, sphere j is object planes + j + 1; a plane is ground
        // when its normal facing the ray is within 15° of up (the room's floor, not its ceiling).
        let mut best: Option<Hit> = None;
        let mut take = |s: f64, r: u8, label: u32, n: [f64; 3]| {
            if s > 1e-6 && s <= self.max_range && best.is_none_or(|b| s < b.range) {
                let n = facing(n, dir);
                best = Some(Hit {
                    range: s,
                    reflectivity: r,
                    label,
                    normal: n,
                });
            }
        };
        for (i, pl) in self.planes.iter().enumerate() {
            let den = dot(pl.normal, dir);
            if den.abs() > 1e-12 {
                let n = facing(pl.normal, dir);
                let label = if is_ground_normal(n) {
                    GROUND
                } else {
                    i as u32 + 1
                };
                take((pl.d - dot(pl.normal, o)) / den, pl.reflectivity, label, n);
            }
        }
        let np = self.planes.len() as u32;
        for (j, sp) in self.spheres.iter().enumerate() {
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
                for s in [-b - r, -b + r] {
                    let p = add(o, scale(dir, s));
                    let n = scale(sub(p, sp.center), 1.0 / sp.radius);
                    take(s, sp.reflectivity, np + j as u32 + 1, n);
                }
            }
        }
        best
    }
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn scale(a: [f64; 3], k: f64) -> [f64; 3] {
    [a[0] * k, a[1] * k, a[2] * k]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        scale(a, 1.0 / n)
    } else {
        a
    }
}

/// `n` flipped to face a ray travelling along `dir`.
fn facing(n: [f64; 3], dir: [f64; 3]) -> [f64; 3] {
    if dot(n, dir) > 0.0 {
        scale(n, -1.0)
    } else {
        n
    }
}

/// Whether a ray-facing unit normal belongs to a ground surface (slope ≤ 15°, facing up).
pub fn is_ground_normal(n: [f64; 3]) -> bool {
    n[2] >= GROUND_MAX_SLOPE_DEG.to_radians().cos()
}

/// A geometric primitive of a [`World`]. Coordinates in metres, world frame (z up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Prim {
    /// The infinite plane `normal · p = d` (`normal` a unit vector). Not culled: tested by
    /// every ray.
    Plane {
        /// Unit normal.
        normal: [f64; 3],
        /// Offset along the normal.
        d: f64,
    },
    /// The parallelogram `p0 + u·e1 + v·e2`, `u, v ∈ [0, 1]` (a bounded ground patch, a ramp,
    /// a wall face).
    Patch {
        /// A corner.
        p0: [f64; 3],
        /// First edge.
        e1: [f64; 3],
        /// Second edge.
        e2: [f64; 3],
    },
    /// A box standing upright, turned by `yaw` about z: `|local x| ≤ half[0]`,
    /// `|local y| ≤ half[1]`, `z ∈ [z0, z1]`.
    Box {
        /// Centre of the footprint (x, y).
        center: [f64; 2],
        /// Half length and half width.
        half: [f64; 2],
        /// Heading of the local x axis, radians counter-clockwise from world x.
        yaw: f64,
        /// Bottom.
        z0: f64,
        /// Top.
        z1: f64,
    },
    /// A vertical cylinder with flat caps (a pole, a trunk).
    Cylinder {
        /// Axis position (x, y).
        center: [f64; 2],
        /// Radius.
        radius: f64,
        /// Bottom.
        z0: f64,
        /// Top.
        z1: f64,
    },
    /// A sphere.
    Sphere {
        /// Centre.
        center: [f64; 3],
        /// Radius.
        radius: f64,
    },
}

/// Distance and unit outward normal of the first intersection of a ray with a primitive.
fn intersect(p: &Prim, o: [f64; 3], d: [f64; 3]) -> Option<(f64, [f64; 3])> {
    const EPS: f64 = 1e-9;
    match *p {
        Prim::Plane { normal, d: off } => {
            let den = dot(normal, d);
            if den.abs() < 1e-12 {
                return None;
            }
            let t = (off - dot(normal, o)) / den;
            (t > EPS).then_some((t, normal))
        }
        Prim::Patch { p0, e1, e2 } => {
            // Möller–Trumbore on a parallelogram.
            let pv = cross(d, e2);
            let det = dot(e1, pv);
            if det.abs() < 1e-14 {
                return None;
            }
            let inv = 1.0 / det;
            let tv = sub(o, p0);
            let u = dot(tv, pv) * inv;
            if !(0.0..=1.0).contains(&u) {
                return None;
            }
            let q = cross(tv, e1);
            let v = dot(d, q) * inv;
            if !(0.0..=1.0).contains(&v) {
                return None;
            }
            let t = dot(e2, q) * inv;
            (t > EPS).then(|| (t, normalize(cross(e1, e2))))
        }
        Prim::Box {
            center,
            half,
            yaw,
            z0,
            z1,
        } => {
            let (s, c) = yaw.sin_cos();
            let (rx, ry) = (o[0] - center[0], o[1] - center[1]);
            let lo = [c * rx + s * ry, -s * rx + c * ry, o[2]];
            let ld = [c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]];
            let lo_b = [-half[0], -half[1], z0];
            let hi_b = [half[0], half[1], z1];
            let (mut tmin, mut tmax) = (f64::NEG_INFINITY, f64::INFINITY);
            let (mut amin, mut smin, mut amax, mut smax) = (0usize, 0.0, 0usize, 0.0);
            for a in 0..3 {
                if ld[a].abs() < 1e-15 {
                    if lo[a] < lo_b[a] || lo[a] > hi_b[a] {
                        return None;
                    }
                    continue;
                }
                let inv = 1.0 / ld[a];
                let (t0, t1) = ((lo_b[a] - lo[a]) * inv, (hi_b[a] - lo[a]) * inv);
                let (tn, tf, sn) = if t0 < t1 {
                    (t0, t1, -1.0)
                } else {
                    (t1, t0, 1.0)
                };
                if tn > tmin {
                    (tmin, amin, smin) = (tn, a, sn);
                }
                if tf < tmax {
                    (tmax, amax, smax) = (tf, a, -sn);
                }
            }
            if tmin > tmax {
                return None;
            }
            let (t, a, sg) = if tmin > EPS {
                (tmin, amin, smin)
            } else if tmax > EPS {
                (tmax, amax, smax)
            } else {
                return None;
            };
            let n = match a {
                0 => [sg * c, sg * s, 0.0],
                1 => [-sg * s, sg * c, 0.0],
                _ => [0.0, 0.0, sg],
            };
            Some((t, n))
        }
        Prim::Cylinder {
            center,
            radius,
            z0,
            z1,
        } => {
            let mut best: Option<(f64, [f64; 3])> = None;
            let mut take = |t: f64, n: [f64; 3]| {
                if t > EPS && best.is_none_or(|b| t < b.0) {
                    best = Some((t, n));
                }
            };
            let (ox, oy) = (o[0] - center[0], o[1] - center[1]);
            let a = d[0] * d[0] + d[1] * d[1];
            if a > 1e-15 {
                let b = ox * d[0] + oy * d[1];
                let c = ox * ox + oy * oy - radius * radius;
                let disc = b * b - a * c;
                if disc >= 0.0 {
                    let r = disc.sqrt();
                    for t in [(-b - r) / a, (-b + r) / a] {
                        let z = o[2] + t * d[2];
                        if (z0..=z1).contains(&z) {
                            let (x, y) = (ox + t * d[0], oy + t * d[1]);
                            take(t, [x / radius, y / radius, 0.0]);
                        }
                    }
                }
            }
            if d[2].abs() > 1e-15 {
                for (zc, nz) in [(z0, -1.0), (z1, 1.0)] {
                    let t = (zc - o[2]) / d[2];
                    let (x, y) = (ox + t * d[0], oy + t * d[1]);
                    if x * x + y * y <= radius * radius {
                        take(t, [0.0, 0.0, nz]);
                    }
                }
            }
            best
        }
        Prim::Sphere { center, radius } => {
            let oc = sub(o, center);
            let b = dot(oc, d);
            let c = dot(oc, oc) - radius * radius;
            let disc = b * b - c;
            if disc < 0.0 {
                return None;
            }
            let r = disc.sqrt();
            let t = if -b - r > EPS { -b - r } else { -b + r };
            (t > EPS).then(|| {
                let p = add(o, scale(d, t));
                (t, scale(sub(p, center), 1.0 / radius))
            })
        }
    }
}

/// Axis-aligned xy bounds `[xmin, ymin, xmax, ymax]` of a primitive (`None`: unbounded).
fn bounds_xy(p: &Prim) -> Option<[f64; 4]> {
    match *p {
        Prim::Plane { .. } => None,
        Prim::Patch { p0, e1, e2 } => {
            let pts = [p0, add(p0, e1), add(p0, e2), add(add(p0, e1), e2)];
            let mut b = [
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ];
            for q in pts {
                b = [
                    b[0].min(q[0]),
                    b[1].min(q[1]),
                    b[2].max(q[0]),
                    b[3].max(q[1]),
                ];
            }
            Some(b)
        }
        Prim::Box {
            center, half, yaw, ..
        } => {
            let (s, c) = yaw.sin_cos();
            let ex = half[0] * c.abs() + half[1] * s.abs();
            let ey = half[0] * s.abs() + half[1] * c.abs();
            Some([
                center[0] - ex,
                center[1] - ey,
                center[0] + ex,
                center[1] + ey,
            ])
        }
        Prim::Cylinder { center, radius, .. } => Some([
            center[0] - radius,
            center[1] - radius,
            center[0] + radius,
            center[1] + radius,
        ]),
        Prim::Sphere { center, radius } => Some([
            center[0] - radius,
            center[1] - radius,
            center[0] + radius,
            center[1] + radius,
        ]),
    }
}

/// A primitive with its label and reflectivity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Object {
    /// The geometry.
    pub prim: Prim,
    /// Object id (≥ 1) reported as the label of its non-ground surfaces.
    pub id: u32,
    /// Ground primitive: surfaces facing up within 15° are labelled [`GROUND`] (roads, kerbs,
    /// sidewalks, ramps); otherwise the whole object is labelled `id`.
    pub ground_by_slope: bool,
    /// Reflectivity reported (0..=255).
    pub reflectivity: u8,
}

impl Object {
    /// An object labelled `id` (≥ 1), reflectivity derived from the id.
    pub fn new(id: u32, prim: Prim) -> Self {
        Self {
            prim,
            id,
            ground_by_slope: false,
            reflectivity: (40 + (id.wrapping_mul(37) % 200)) as u8,
        }
    }

    /// A ground primitive (id 1 for its steep faces until [`Self::with_id`]): surfaces within
    /// 15° of horizontal are [`GROUND`].
    pub fn ground(prim: Prim) -> Self {
        Self {
            prim,
            id: 1,
            ground_by_slope: true,
            reflectivity: 25,
        }
    }

    /// The same object with another id.
    pub fn with_id(mut self, id: u32) -> Self {
        self.id = id;
        self
    }

    /// The same object with another reflectivity.
    pub fn with_reflectivity(mut self, r: u8) -> Self {
        self.reflectivity = r;
        self
    }

    /// First hit of a ray (unit `dir`) on this object alone.
    pub fn cast(&self, o: [f64; 3], dir: [f64; 3]) -> Option<Hit> {
        let (t, n) = intersect(&self.prim, o, dir)?;
        let n = facing(n, dir);
        let label = if self.ground_by_slope && is_ground_normal(n) {
            GROUND
        } else {
            self.id
        };
        Some(Hit {
            range: t,
            reflectivity: self.reflectivity,
            label,
            normal: n,
        })
    }
}

/// A scene of [`Object`]s culled by a 2-D uniform grid over xy: a ray visits the cells it
/// crosses, nearest first, tests the objects listed there and stops at the first cell whose
/// far edge lies beyond the nearest hit found. Unbounded planes are tested by every ray.
#[derive(Clone, Debug)]
pub struct World {
    objects: Vec<Object>,
    unbounded: Vec<u32>,
    cell: f64,
    origin: [f64; 2],
    nx: usize,
    ny: usize,
    /// CSR: objects of cell `i` are `items[starts[i]..starts[i + 1]]`.
    starts: Vec<u32>,
    items: Vec<u32>,
    /// Rays travelling farther than this return nothing.
    pub max_range: f64,
}

/// Cell edge of the culling grid, metres.
pub const GRID_CELL_M: f64 = 4.0;

impl World {
    /// A world of `objects`; rays farther than `max_range` return nothing.
    pub fn new(objects: Vec<Object>, max_range: f64) -> Self {
        let cell = GRID_CELL_M;
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let mut unbounded = Vec::new();
        let bounds: Vec<Option<[f64; 4]>> = objects.iter().map(|o| bounds_xy(&o.prim)).collect();
        for (i, b) in bounds.iter().enumerate() {
            match b {
                Some(b) => {
                    lo = [lo[0].min(b[0]), lo[1].min(b[1])];
                    hi = [hi[0].max(b[2]), hi[1].max(b[3])];
                }
                None => unbounded.push(i as u32),
            }
        }
        if lo[0] > hi[0] {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        let origin = [lo[0] - cell, lo[1] - cell];
        let nx = ((hi[0] - origin[0]) / cell).ceil() as usize + 1;
        let ny = ((hi[1] - origin[1]) / cell).ceil() as usize + 1;
        let mut per_cell: Vec<Vec<u32>> = vec![Vec::new(); nx * ny];
        for (i, b) in bounds.iter().enumerate() {
            let Some(b) = b else { continue };
            let cx0 = ((b[0] - origin[0]) / cell).floor().max(0.0) as usize;
            let cy0 = ((b[1] - origin[1]) / cell).floor().max(0.0) as usize;
            let cx1 = (((b[2] - origin[0]) / cell).floor() as usize).min(nx - 1);
            let cy1 = (((b[3] - origin[1]) / cell).floor() as usize).min(ny - 1);
            for cy in cy0..=cy1 {
                for cx in cx0..=cx1 {
                    per_cell[cy * nx + cx].push(i as u32);
                }
            }
        }
        let mut starts = Vec::with_capacity(nx * ny + 1);
        let mut items = Vec::new();
        starts.push(0);
        for c in per_cell {
            items.extend(c);
            starts.push(items.len() as u32);
        }
        Self {
            objects,
            unbounded,
            cell,
            origin,
            nx,
            ny,
            starts,
            items,
            max_range,
        }
    }

    /// The objects, in the order given.
    pub fn objects(&self) -> &[Object] {
        &self.objects
    }

    /// The same ray cast by testing every object (no culling): the reference the grid walk is
    /// checked against.
    pub fn cast_brute_force(&self, o: [f64; 3], dir: [f64; 3]) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for ob in &self.objects {
            if let Some(h) = ob.cast(o, dir) {
                if h.range <= self.max_range && best.is_none_or(|b| h.range < b.range) {
                    best = Some(h);
                }
            }
        }
        best
    }
}

impl Scene for World {
    fn cast(&self, o: [f64; 3], dir: [f64; 3]) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let test = |i: u32, best: &mut Option<Hit>| {
            if let Some(h) = self.objects[i as usize].cast(o, dir) {
                if h.range <= self.max_range && best.is_none_or(|b| h.range < b.range) {
                    *best = Some(h);
                }
            }
        };
        for &i in &self.unbounded {
            test(i, &mut best);
        }
        // Clip the ray's xy projection to the grid, then walk the cells (Amanatides & Woo).
        let c = self.cell;
        let gx1 = self.origin[0] + self.nx as f64 * c;
        let gy1 = self.origin[1] + self.ny as f64 * c;
        let mut t_in = 0.0f64;
        let mut t_out = best.map_or(self.max_range, |b| b.range);
        for (a, (g0, g1)) in [(self.origin[0], gx1), (self.origin[1], gy1)]
            .into_iter()
            .enumerate()
        {
            if dir[a].abs() < 1e-15 {
                if o[a] < g0 || o[a] >= g1 {
                    return best;
                }
            } else {
                let (ta, tb) = ((g0 - o[a]) / dir[a], (g1 - o[a]) / dir[a]);
                t_in = t_in.max(ta.min(tb));
                t_out = t_out.min(ta.max(tb));
            }
        }
        if t_in > t_out {
            return best;
        }
        let px = o[0] + t_in * dir[0] - self.origin[0];
        let py = o[1] + t_in * dir[1] - self.origin[1];
        let mut cx = ((px / c).floor().max(0.0) as usize).min(self.nx - 1) as i64;
        let mut cy = ((py / c).floor().max(0.0) as usize).min(self.ny - 1) as i64;
        let axis = |d: f64, p: f64, cell: i64| -> (i64, f64, f64) {
            if d > 1e-15 {
                (1, ((cell + 1) as f64 * c - p) / d, c / d)
            } else if d < -1e-15 {
                (-1, (cell as f64 * c - p) / d, -c / d)
            } else {
                (0, f64::INFINITY, f64::INFINITY)
            }
        };
        let (sx, mut tmx, dx) = axis(dir[0], px, cx);
        let (sy, mut tmy, dy) = axis(dir[1], py, cy);
        let (nx, ny) = (self.nx as i64, self.ny as i64);
        loop {
            let k = (cy * nx + cx) as usize;
            for j in self.starts[k]..self.starts[k + 1] {
                test(self.items[j as usize], &mut best);
            }
            let t_exit = t_in + tmx.min(tmy);
            if best.is_some_and(|b| b.range <= t_exit) || t_exit >= t_out {
                return best;
            }
            if tmx < tmy {
                cx += sx;
                tmx += dx;
            } else {
                cy += sy;
                tmy += dy;
            }
            if cx < 0 || cy < 0 || cx >= nx || cy >= ny {
                return best;
            }
        }
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

    #[test]
    fn grid_walk_finds_the_same_hits_as_testing_every_object() {
        let w = crate::sim::scenes::urban();
        let mut x = 0x1234_5678_9ABC_DEF0u64;
        let mut rnd = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut hits = 0;
        for _ in 0..20_000 {
            let o = [
                rnd() * 170.0 - 10.0,
                rnd() * 120.0 - 10.0,
                0.3 + rnd() * 3.0,
            ];
            let az = rnd() * std::f64::consts::TAU;
            let el = (rnd() - 0.7) * 0.8;
            let d = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
            let a = w.cast(o, d);
            let b = w.cast_brute_force(o, d);
            assert_eq!(a, b, "ray {o:?} {d:?}");
            hits += usize::from(a.is_some_and(|h| h.label != GROUND));
        }
        assert!(hits > 5_000, "objects are hit ({hits})");
    }

    #[test]
    fn primitives_hit_where_the_geometry_says() {
        let yawed = Object::new(
            3,
            Prim::Box {
                center: [10.0, 0.0],
                half: [2.0, 1.0],
                yaw: std::f64::consts::FRAC_PI_2,
                z0: 0.0,
                z1: 2.0,
            },
        );
        // Turned 90°: the box spans x ∈ [9, 11], y ∈ [−2, 2].
        let h = yawed.cast([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]).unwrap();
        assert!((h.range - 9.0).abs() < 1e-12);
        assert!((h.normal[0] + 1.0).abs() < 1e-12 && h.label == 3);
        let h = yawed.cast([10.0, 1.9, 5.0], [0.0, 0.0, -1.0]).unwrap();
        assert!((h.range - 3.0).abs() < 1e-12 && h.normal == [0.0, 0.0, 1.0]);
        assert!(yawed.cast([10.0, 2.1, 5.0], [0.0, 0.0, -1.0]).is_none());
        let cyl = Object::new(
            4,
            Prim::Cylinder {
                center: [0.0, 5.0],
                radius: 0.5,
                z0: 0.0,
                z1: 3.0,
            },
        );
        let h = cyl.cast([0.0, 0.0, 1.0], [0.0, 1.0, 0.0]).unwrap();
        assert!((h.range - 4.5).abs() < 1e-12);
        assert!(cyl.cast([0.0, 0.0, 3.5], [0.0, 1.0, 0.0]).is_none());
        let s2 = std::f64::consts::FRAC_1_SQRT_2;
        let h = cyl.cast([0.0, 0.0, 5.0], [0.0, s2, -s2]).unwrap();
        // Through the top cap at z = 3 (y = 2 is short of the cylinder): the side at y = 4.5.
        assert!((h.range - 4.5 * 2f64.sqrt()).abs() < 1e-9);
        let ramp = Object::ground(Prim::Patch {
            p0: [0.0, -1.0, 0.0],
            e1: [10.0, 0.0, 10.0f64.to_radians().tan() * 10.0],
            e2: [0.0, 2.0, 0.0],
        });
        let steep = Object::ground(Prim::Patch {
            p0: [0.0, -1.0, 0.0],
            e1: [10.0, 0.0, 20.0f64.to_radians().tan() * 10.0],
            e2: [0.0, 2.0, 0.0],
        });
        let down = [0.0, 0.0, -1.0];
        assert_eq!(ramp.cast([5.0, 0.0, 9.0], down).unwrap().label, GROUND);
        assert_eq!(steep.cast([5.0, 0.0, 9.0], down).unwrap().label, 1);
    }
}
