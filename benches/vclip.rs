//! V-Clip query throughput, cold and warm-started, against parry3d-f64's
//! GJK `query::distance` on the same poses. Run with
//! `cargo bench --bench vclip`; prints a table.
//!
//! Each scenario moves B along a smooth path near A (a simulation-like
//! sequence of frames, B within about a tenth of its size of A's surface,
//! sometimes touching or overlapping): "warm" queries each frame from the
//! previous frame's features, "cold" from no cache, parry from scratch.

use std::hint::black_box;
use std::time::Instant;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::math::{Pose as PPose, Rotation as PRot, Vector as PVec};
use parry3d_f64::query;
use parry3d_f64::shape::ConvexPolyhedron as ParryPoly;
use rigidsim::collision::vclip::{FeaturePair, closest_features};
use rigidsim::polyhedron::ConvexPolyhedron;

const FRAMES: usize = 2000;
/// Each measurement repeats the path until it has run this long.
const MIN_SECONDS: f64 = 0.3;

fn cuboid(hx: f64, hy: f64, hz: f64) -> ConvexPolyhedron {
    let pts: Vec<_> = (0..8)
        .map(|i| {
            Vector3::new(
                if i & 1 == 0 { -hx } else { hx },
                if i & 2 == 0 { -hy } else { hy },
                if i & 4 == 0 { -hz } else { hz },
            )
        })
        .collect();
    ConvexPolyhedron::hull(&pts).unwrap()
}

/// Hull of a Fibonacci lattice on the sphere: 2n − 4 triangles.
fn geodesic(n: usize, r: f64) -> ConvexPolyhedron {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let pts: Vec<_> = (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rad = (1.0 - y * y).sqrt();
            let t = golden * i as f64;
            Vector3::new(rad * t.cos(), y, rad * t.sin()) * r
        })
        .collect();
    ConvexPolyhedron::hull(&pts).unwrap()
}

/// Right prism over a regular n-gon: n + 2 faces.
fn prism(n: usize, r: f64, hz: f64) -> ConvexPolyhedron {
    let mut pts = Vec::new();
    for z in [-hz, hz] {
        for k in 0..n {
            let t = std::f64::consts::TAU * k as f64 / n as f64;
            pts.push(Vector3::new(r * t.cos(), r * t.sin(), z));
        }
    }
    ConvexPolyhedron::hull(&pts).unwrap()
}

fn to_parry(p: &ConvexPolyhedron) -> ParryPoly {
    let pts: Vec<PVec> = p
        .vertices()
        .iter()
        .map(|x| PVec::new(x.x, x.y, x.z))
        .collect();
    ParryPoly::from_convex_hull(&pts).unwrap()
}

fn to_pose(iso: &Isometry3<f64>) -> PPose {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    PPose::from_parts(
        PVec::new(t.x, t.y, t.z),
        PRot::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

/// B circling A at a radius that breathes between touching and a tenth of
/// the pair's size apart, turning as it goes.
fn orbit(reach: f64) -> Vec<Isometry3<f64>> {
    (0..FRAMES)
        .map(|k| {
            let t = k as f64 / FRAMES as f64;
            let dir = Vector3::new(
                (7.0 * t).cos() * (3.0 * t).cos(),
                (7.0 * t).sin() * (3.0 * t).cos(),
                (3.0 * t).sin(),
            );
            let radius = reach * (0.93 + 0.1 * (29.0 * t).sin());
            let rot = UnitQuaternion::from_scaled_axis(Vector3::new(5.0 * t, -3.0 * t, 2.0 * t));
            Isometry3::from_parts(Translation3::from(dir * radius), rot)
        })
        .collect()
}

/// A 1 m box gliding and yawing over a floor whose top is z = 0, bouncing
/// between resting on it and 5 cm above, tilting a little.
fn over_floor() -> Vec<Isometry3<f64>> {
    (0..FRAMES)
        .map(|k| {
            let t = k as f64 / FRAMES as f64;
            let height =
                0.5 + 0.05 * (1.0 + (40.0 * t).sin()) / 2.0 + 0.1 * (1.0 - (40.0 * t).cos());
            let rot = UnitQuaternion::from_euler_angles(
                0.05 * (11.0 * t).sin(),
                0.05 * (13.0 * t).cos(),
                6.0 * t,
            );
            Isometry3::from_parts(
                Translation3::new(3.0 * (2.0 * t).sin(), 3.0 * (3.0 * t).cos(), height),
                rot,
            )
        })
        .collect()
}

/// Runs `f` over the path until MIN_SECONDS have passed; queries per second.
fn rate(mut f: impl FnMut() -> u64) -> (f64, f64) {
    let start = Instant::now();
    let (mut queries, mut iterations) = (0u64, 0u64);
    while start.elapsed().as_secs_f64() < MIN_SECONDS {
        iterations += f();
        queries += FRAMES as u64;
    }
    let secs = start.elapsed().as_secs_f64();
    (queries as f64 / secs, iterations as f64 / queries as f64)
}

fn main() {
    let sphere = geodesic(102, 0.1);
    let floor = cuboid(5.0, 5.0, 0.5);
    let cube = cuboid(0.5, 0.5, 0.5);
    let prism = prism(98, 0.5, 0.2);
    // (name, A, B, path of (pose A, pose B) per frame)
    let fixed = |p: Isometry3<f64>| vec![p; FRAMES];
    let scenarios = [
        (
            "geodesic 200 f vs geodesic 200 f",
            &sphere,
            &sphere,
            fixed(Isometry3::identity()),
            orbit(2.0 * sphere.bounding_sphere().1),
        ),
        // The box (A) moves over the fixed floor (B).
        (
            "box vs floor box",
            &cube,
            &floor,
            over_floor(),
            fixed(Isometry3::translation(0.0, 0.0, -0.5)),
        ),
        (
            "prism 100 f vs box",
            &prism,
            &cube,
            fixed(Isometry3::identity()),
            orbit(prism.bounding_sphere().1 + 0.6),
        ),
    ];

    println!(
        "{:<34} {:>5} {:>5} | {:>13} {:>6} | {:>13} {:>6} | {:>13}",
        "pair", "F_A", "F_B", "cold q/s", "iters", "warm q/s", "iters", "parry GJK q/s"
    );
    for (name, a, b, poses_a, poses_b) in scenarios {
        let cold = rate(|| {
            let mut its = 0;
            for (pa, pb) in poses_a.iter().zip(&poses_b) {
                let r = closest_features(a, pa, b, pb, None);
                its += r.iterations as u64;
                black_box(r.distance);
            }
            its
        });
        let warm = rate(|| {
            let mut its = 0;
            let mut cache: Option<FeaturePair> = None;
            for (pa, pb) in poses_a.iter().zip(&poses_b) {
                let r = closest_features(a, pa, b, pb, cache);
                cache = Some(r.features);
                its += r.iterations as u64;
                black_box(r.distance);
            }
            its
        });
        let (sa, sb) = (to_parry(a), to_parry(b));
        let parry_poses: Vec<(PPose, PPose)> = poses_a
            .iter()
            .zip(&poses_b)
            .map(|(pa, pb)| (to_pose(pa), to_pose(pb)))
            .collect();
        let parry = rate(|| {
            for (pa, pb) in &parry_poses {
                black_box(query::distance(pa, &sa, pb, &sb).unwrap().distance);
            }
            0
        });
        println!(
            "{:<34} {:>5} {:>5} | {:>13.0} {:>6.2} | {:>13.0} {:>6.2} | {:>13.0}",
            name,
            a.face_count(),
            b.face_count(),
            cold.0,
            cold.1,
            warm.0,
            warm.1,
            parry.0
        );
    }
}
