//! Criterion benchmark of the simulator's ray casting (`sim::scene::World`) and packet
//! generation with a moving sensor.
//!
//! ```text
//! cargo bench --bench sim_cast
//! ```
//! Rays: the HDL-32E's 32 beams (its built-in table) every 0.2° of azimuth, from 20 sensor
//! poses along the urban route (`Route::urban`, sensor 1.8 m up), cast into `scenes::urban()`
//! (≈ 170 boxes, cylinders and ground boxes). Throughput in elements = rays.
//!
//! * `cast/grid`: `World::cast` (2-D grid walk) — the simulator's path;
//! * `cast/brute_force`: `World::cast_brute_force` (every object per ray) on the same rays —
//!   the speed-up of the culling is the ratio of the two;
//! * `packet/hdl32e_urban_route`: `VelodyneSim::next_packet` of an HDL-32E driving the route
//!   (pose per firing, cast, encode); elements = measurements (384 per packet). An HDL-32E
//!   needs 694,000 measurements per second of sensor time (1808 packets/s);
//! * `packet/hdl32e_urban_fixed_pose`: the same from a fixed pose on the first street (no
//!   pose evaluation per firing): the cost of the motion is the ratio of the two.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::{Point3, Vector3};
use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sim::motion::Route;
use ringscan::sim::motion::Trajectory;
use ringscan::sim::scene::Scene;
use ringscan::sim::scenes;

fn rays() -> Vec<([f64; 3], [f64; 3])> {
    let calib = builtin(VelodyneModel::Hdl32e).expect("built-in HDL-32E table");
    let route = Route::urban();
    let dur = route.duration_s();
    let traj = Trajectory::route(0, route);
    let mut out = Vec::new();
    for k in 0..20 {
        let pose = traj.pose_s(dur * f64::from(k) / 20.0);
        let o = pose * Point3::origin();
        for a in 0..1800 {
            let az = (f64::from(a) * 0.2).to_radians();
            for l in &calib.lasers {
                let (sw, cw) = l.vert_correction.sin_cos();
                let d = pose.rotation * Vector3::new(cw * az.cos(), cw * az.sin(), sw);
                out.push((o.coords.into(), d.into()));
            }
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    let world = scenes::urban();
    let rays = rays();
    let mut g = c.benchmark_group("cast");
    g.throughput(Throughput::Elements(rays.len() as u64));
    g.sample_size(10);
    g.bench_function("grid", |b| {
        b.iter(|| {
            let mut hits = 0usize;
            for &(o, d) in &rays {
                hits += usize::from(world.cast(o, d).is_some());
            }
            black_box(hits)
        })
    });
    g.bench_function("brute_force", |b| {
        b.iter(|| {
            let mut hits = 0usize;
            for &(o, d) in &rays {
                hits += usize::from(world.cast_brute_force(o, d).is_some());
            }
            black_box(hits)
        })
    });
    g.finish();

    let model = VelodyneModel::Hdl32e;
    let calib = builtin(model).expect("built-in HDL-32E table");
    let mut sim = VelodyneSim::new(model, ReturnMode::Strongest, calib, 0);
    sim.trajectory = Trajectory::route(0, Route::urban());
    let mut g = c.benchmark_group("packet");
    g.throughput(Throughput::Elements(384));
    let mut truth = Vec::new();
    g.bench_function("hdl32e_urban_route", |b| {
        b.iter(|| {
            truth.clear();
            // Wrap around the route so that every sample drives the same stretch mix.
            if sim.packet_index > 60_000 {
                sim.packet_index = 0;
            }
            black_box(sim.next_packet(&world, &mut truth))
        })
    });
    let calib = builtin(model).expect("built-in HDL-32E table");
    let mut fixed = VelodyneSim::new(model, ReturnMode::Strongest, calib, 0);
    fixed.trajectory = Trajectory::fixed(nalgebra::Isometry3::translation(40.0, 0.0, 1.8));
    g.bench_function("hdl32e_urban_fixed_pose", |b| {
        b.iter(|| {
            truth.clear();
            black_box(fixed.next_packet(&world, &mut truth))
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
