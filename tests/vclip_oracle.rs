//! V-Clip against an independent oracle (parry3d-f64's GJK/EPA) and against
//! hand-built degenerate cases; polyhedron construction; contact manifolds.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::math::{Pose as PPose, Rotation as PRot, Vector as PVec};
use parry3d_f64::query;
use parry3d_f64::shape::ConvexPolyhedron as ParryPoly;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rigidsim::collision::manifold::{ContactPoint, contact_points};
use rigidsim::collision::vclip::{
    Feature, FeaturePair, Proximity, closest_features, closest_features_with_limit, exhaustive,
    separating_axis,
};
use rigidsim::polyhedron::{ConvexPolyhedron, PolyhedronError, weld};

// ---------------------------------------------------------------- shapes

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

/// Box with half extents (hx, hy, hz), as 6 quads.
fn cuboid(hx: f64, hy: f64, hz: f64) -> ConvexPolyhedron {
    let (verts, quads) = cuboid_mesh(hx, hy, hz);
    ConvexPolyhedron::from_faces(verts, quads).unwrap()
}

fn cuboid_mesh(hx: f64, hy: f64, hz: f64) -> (Vec<Vector3<f64>>, Vec<Vec<usize>>) {
    let verts = (0..8)
        .map(|i| {
            v(
                if i & 1 == 0 { -hx } else { hx },
                if i & 2 == 0 { -hy } else { hy },
                if i & 4 == 0 { -hz } else { hz },
            )
        })
        .collect();
    let quads = vec![
        vec![0, 2, 3, 1], // z = -hz
        vec![4, 5, 7, 6], // z = +hz
        vec![0, 1, 5, 4], // y = -hy
        vec![2, 6, 7, 3], // y = +hy
        vec![0, 4, 6, 2], // x = -hx
        vec![1, 3, 7, 5], // x = +hx
    ];
    (verts, quads)
}

fn cube_triangles() -> (Vec<Vector3<f64>>, Vec<Vec<usize>>) {
    let (verts, quads) = cuboid_mesh(0.5, 0.5, 0.5);
    let tris = quads
        .iter()
        .flat_map(|q| [vec![q[0], q[1], q[2]], vec![q[0], q[2], q[3]]])
        .collect();
    (verts, tris)
}

/// Right prism over a regular n-gon of circumradius r, height 2 hz.
fn prism(n: usize, r: f64, hz: f64) -> ConvexPolyhedron {
    let mut verts = Vec::new();
    for z in [-hz, hz] {
        for k in 0..n {
            let t = std::f64::consts::TAU * k as f64 / n as f64;
            verts.push(v(r * t.cos(), r * t.sin(), z));
        }
    }
    let mut faces = vec![(0..n).rev().collect::<Vec<_>>(), (n..2 * n).collect()];
    for k in 0..n {
        let k1 = (k + 1) % n;
        faces.push(vec![k, k1, n + k1, n + k]);
    }
    ConvexPolyhedron::from_faces(verts, faces).unwrap()
}

/// Hull of points spread evenly over a sphere (Fibonacci lattice): a
/// geodesic-like polyhedron with about 2 n − 4 triangles.
fn geodesic(n: usize, r: f64) -> ConvexPolyhedron {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let pts: Vec<_> = (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rad = (1.0 - y * y).sqrt();
            let t = golden * i as f64;
            v(rad * t.cos(), y, rad * t.sin()) * r
        })
        .collect();
    ConvexPolyhedron::hull(&pts).unwrap()
}

fn random_shape(rng: &mut ChaCha8Rng) -> ConvexPolyhedron {
    let s = rng.random_range(0.3..1.5);
    match rng.random_range(0..4) {
        0 => cuboid(
            s * rng.random_range(0.2..1.0),
            s * rng.random_range(0.2..1.0),
            s * rng.random_range(0.2..1.0),
        ),
        1 => prism(rng.random_range(3..12), s, s * rng.random_range(0.1..1.0)),
        _ => {
            let n = rng.random_range(4..40);
            let scale = v(
                rng.random_range(0.3..1.0),
                rng.random_range(0.3..1.0),
                rng.random_range(0.3..1.0),
            ) * s;
            let pts: Vec<_> = (0..n)
                .map(|_| {
                    v(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    )
                    .component_mul(&scale)
                })
                .collect();
            ConvexPolyhedron::hull(&pts).unwrap()
        }
    }
}

fn random_rotation(rng: &mut ChaCha8Rng) -> UnitQuaternion<f64> {
    let q = nalgebra::Quaternion::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    UnitQuaternion::from_quaternion(q)
}

fn random_direction(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    loop {
        let d = v(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        if d.norm() > 0.1 && d.norm() <= 1.0 {
            return d.normalize();
        }
    }
}

fn pose(t: Vector3<f64>, r: UnitQuaternion<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(t), r)
}

fn at(x: f64, y: f64, z: f64) -> Isometry3<f64> {
    Isometry3::translation(x, y, z)
}

// ---------------------------------------------------------------- oracle

struct Oracle {
    shape_a: ParryPoly,
    shape_b: ParryPoly,
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

impl Oracle {
    fn new(a: &ConvexPolyhedron, b: &ConvexPolyhedron) -> Self {
        Oracle {
            shape_a: to_parry(a),
            shape_b: to_parry(b),
        }
    }

    /// parry's distance (0 when overlapping) and signed contact distance
    /// (negative when overlapping).
    fn query(&self, pa: &Isometry3<f64>, pb: &Isometry3<f64>) -> (f64, f64) {
        let (pa, pb) = (to_pose(pa), to_pose(pb));
        let d = query::distance(&pa, &self.shape_a, &pb, &self.shape_b)
            .unwrap()
            .distance;
        let signed = query::contact(&pa, &self.shape_a, &pb, &self.shape_b, 0.0)
            .unwrap()
            .map_or(d, |c| c.dist);
        (d, signed)
    }
}

/// Largest signed distance of `x` (world) outside `p` at `pose`.
fn outside(p: &ConvexPolyhedron, pose: &Isometry3<f64>, x: &Vector3<f64>) -> f64 {
    let local = pose.inverse_transform_point(&(*x).into()).coords;
    p.faces()
        .iter()
        .map(|f| f.normal.dot(&local) - f.offset)
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Checks a separated answer's self-consistency: the witness points lie on
/// their polyhedra and are `distance` apart.
fn assert_consistent(
    a: &ConvexPolyhedron,
    pa: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pb: &Isometry3<f64>,
    r: &Proximity,
) {
    let size = a.scale().max(b.scale());
    assert!(
        ((r.point_a - r.point_b).norm() - r.distance.abs()).abs() <= 1e-12 * size,
        "{r:?}"
    );
    assert!(
        outside(a, pa, &r.point_a) <= 1e-9 * size,
        "point_a off A: {r:?}"
    );
    assert!(
        outside(b, pb, &r.point_b) <= 1e-9 * size,
        "point_b off B: {r:?}"
    );
}

/// 2000 random pairs (boxes, prisms, hulls of 4–40 random points; random
/// rotations; centres 0–2.5 sizes apart, so about a third overlap).
/// Distance agrees with parry to 1e-9 relative plus 1e-12 of the body size
/// (GJK's own stopping slack); the penetration flag agrees except within
/// 1e-9 of the body size of touching, where either answer is right.
#[test]
fn random_pairs_agree_with_parry_distance_and_overlap() {
    let mut rng = ChaCha8Rng::seed_from_u64(20240601);
    let (mut separated, mut overlapping, mut fell_back) = (0, 0, 0);
    let mut worst_rel: f64 = 0.0;
    for case in 0..2000 {
        let a = random_shape(&mut rng);
        let b = random_shape(&mut rng);
        let pa = pose(
            random_direction(&mut rng) * rng.random_range(0.0..0.5),
            random_rotation(&mut rng),
        );
        let reach = a.bounding_sphere().1 + b.bounding_sphere().1;
        let pb = pose(
            pa.translation.vector + random_direction(&mut rng) * rng.random_range(0.0..1.2) * reach,
            random_rotation(&mut rng),
        );
        let r = closest_features(&a, &pa, &b, &pb, None);
        let (d, signed) = Oracle::new(&a, &b).query(&pa, &pb);
        let size = a.scale().max(b.scale());
        fell_back += r.fell_back as u32;
        if signed.abs() > 1e-9 * size {
            assert_eq!(
                r.penetrating,
                signed < 0.0,
                "case {case}: vclip {r:?}, parry {signed}"
            );
        }
        if r.penetrating {
            overlapping += 1;
            assert!(r.distance <= 0.0);
            continue;
        }
        separated += 1;
        assert_consistent(&a, &pa, &b, &pb, &r);
        let err = (r.distance - d).abs();
        worst_rel = worst_rel.max(err / d.max(1e-300));
        assert!(
            err <= 1e-9 * d + 1e-12 * size,
            "case {case}: vclip {} parry {d}: {r:?}",
            r.distance
        );
    }
    println!(
        "separated {separated}, overlapping {overlapping}, fell back {fell_back}, worst relative error {worst_rel:e}"
    );
    assert!(separated > 500 && overlapping > 300);
    assert_eq!(
        fell_back, 0,
        "the walk should converge on generic random input"
    );
}

/// The exhaustive search is the fallback's answer: check it against V-Clip
/// on the same random pairs, overlapping ones included.
#[test]
fn exhaustive_search_agrees_with_vclip() {
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    for case in 0..300 {
        let a = random_shape(&mut rng);
        let b = random_shape(&mut rng);
        let pa = pose(v(0.0, 0.0, 0.0), random_rotation(&mut rng));
        let reach = a.bounding_sphere().1 + b.bounding_sphere().1;
        let pb = pose(
            random_direction(&mut rng) * rng.random_range(0.0..1.2) * reach,
            random_rotation(&mut rng),
        );
        let r = closest_features(&a, &pa, &b, &pb, None);
        let x = exhaustive(&a, &pa, &b, &pb);
        let size = a.scale().max(b.scale());
        if x.distance.abs() > 1e-9 * size {
            assert_eq!(r.penetrating, x.penetrating, "case {case}");
        }
        if !r.penetrating {
            assert!(
                (r.distance - x.distance).abs() <= 1e-12 * size,
                "case {case}: {r:?} {x:?}"
            );
            assert_consistent(&a, &pa, &b, &pb, &x);
        }
    }
}

/// The iteration bound (cycle guard) forced down to 0–3 states: the fallback
/// answer must match the unbounded walk.
#[test]
fn cycle_guard_fallback_still_answers_correctly() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut fallbacks = 0;
    for case in 0..300 {
        let a = random_shape(&mut rng);
        let b = random_shape(&mut rng);
        let pa = pose(v(0.0, 0.0, 0.0), random_rotation(&mut rng));
        let reach = a.bounding_sphere().1 + b.bounding_sphere().1;
        let pb = pose(
            random_direction(&mut rng) * rng.random_range(0.0..1.2) * reach,
            random_rotation(&mut rng),
        );
        let full = closest_features(&a, &pa, &b, &pb, None);
        let limit = rng.random_range(0..4);
        let cut = closest_features_with_limit(&a, &pa, &b, &pb, None, limit);
        assert!(cut.iterations <= limit);
        if !cut.fell_back {
            continue;
        }
        fallbacks += 1;
        let size = a.scale().max(b.scale());
        if full.distance.abs() > 1e-9 * size {
            assert_eq!(cut.penetrating, full.penetrating, "case {case}");
        }
        if !full.penetrating {
            assert!(
                (cut.distance - full.distance).abs() <= 1e-12 * size,
                "case {case}: {cut:?} {full:?}"
            );
        } else {
            assert!(cut.distance <= 0.0);
        }
    }
    assert!(fallbacks > 200);
}

/// Coherence: a pair moved by 1e-3 of its size and rotated by 1e-3 rad,
/// warm-started from the previous features, gives the cold answer (to 1e-12
/// of the size) in fewer states on average.
#[test]
fn warm_start_after_small_motion_matches_cold_in_fewer_iterations() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (mut warm_total, mut cold_total, mut compared) = (0u64, 0u64, 0);
    for _ in 0..400 {
        let a = if rng.random_bool(0.5) {
            geodesic(60, 1.0)
        } else {
            random_shape(&mut rng)
        };
        let b = random_shape(&mut rng);
        let pa = pose(v(0.0, 0.0, 0.0), random_rotation(&mut rng));
        let reach = a.bounding_sphere().1 + b.bounding_sphere().1;
        let mut pb = pose(
            random_direction(&mut rng) * rng.random_range(0.8..1.3) * reach,
            random_rotation(&mut rng),
        );
        let mut cached = closest_features(&a, &pa, &b, &pb, None).features;
        for _ in 0..5 {
            let nudge = random_direction(&mut rng) * 1e-3 * reach;
            let turn = UnitQuaternion::from_scaled_axis(random_direction(&mut rng) * 1e-3);
            pb = pose(pb.translation.vector + nudge, turn * pb.rotation);
            let warm = closest_features(&a, &pa, &b, &pb, Some(cached));
            let cold = closest_features(&a, &pa, &b, &pb, None);
            assert_eq!(warm.penetrating, cold.penetrating);
            if !cold.penetrating {
                assert!(
                    (warm.distance - cold.distance).abs() <= 1e-12 * reach,
                    "{warm:?} {cold:?}"
                );
                warm_total += warm.iterations as u64;
                cold_total += cold.iterations as u64;
                compared += 1;
            }
            cached = warm.features;
        }
    }
    println!(
        "{compared} re-queries: warm {:.2} states on average, cold {:.2}",
        warm_total as f64 / compared as f64,
        cold_total as f64 / compared as f64
    );
    assert!(compared > 1000);
    assert!(warm_total < cold_total);
}

#[test]
fn stale_or_invalid_warm_starts_do_not_panic() {
    let a = cuboid(0.5, 0.5, 0.5);
    let b = prism(7, 0.6, 0.3);
    let (pa, pb) = (at(0.0, 0.0, 0.0), at(0.3, 0.2, 1.5));
    let cold = closest_features(&a, &pa, &b, &pb, None);
    let bad = [
        FeaturePair {
            a: Feature::Vertex(8),
            b: Feature::Vertex(0),
        },
        FeaturePair {
            a: Feature::Edge(12),
            b: Feature::Edge(0),
        },
        FeaturePair {
            a: Feature::Face(0),
            b: Feature::Face(99),
        },
        FeaturePair {
            a: Feature::Face(u32::MAX),
            b: Feature::Vertex(u32::MAX),
        },
        FeaturePair {
            a: Feature::Face(3),
            b: Feature::Face(2),
        },
        FeaturePair {
            a: Feature::Edge(11),
            b: Feature::Face(8),
        },
        FeaturePair {
            a: Feature::Face(5),
            b: Feature::Edge(20),
        },
    ];
    for start in bad {
        let r = closest_features(&a, &pa, &b, &pb, Some(start));
        assert!(
            (r.distance - cold.distance).abs() < 1e-12,
            "{start:?}: {r:?}"
        );
    }
}

// ---------------------------------------------------------------- degenerate

/// Exactly parallel, coincident faces: a 1 m cube centred 1 m above another.
#[test]
fn box_on_box_with_coincident_faces_touches_at_zero_distance() {
    let a = cuboid(0.5, 0.5, 0.5);
    for (x, y) in [(0.0, 0.0), (0.25, -0.1), (1.0, 0.0), (1.0, 1.0)] {
        let r = closest_features(&a, &at(x, y, 1.0), &a, &at(0.0, 0.0, 0.0), None);
        assert!(!r.penetrating || r.distance == 0.0, "{r:?}");
        assert!(r.distance.abs() < 1e-15, "{r:?}");
    }
}

/// Parallel faces with a gap, stacked exactly and offset, all starts.
#[test]
fn parallel_faces_give_the_gap() {
    let a = cuboid(0.5, 0.5, 0.5);
    let b = cuboid(2.0, 2.0, 0.5);
    for gap in [1e-9, 1e-3, 0.37] {
        for (x, y) in [(0.0, 0.0), (1.5, 1.5), (2.0, 0.3), (2.5, 0.0)] {
            for start in [
                None,
                Some(FeaturePair {
                    a: Feature::Face(0),
                    b: Feature::Vertex(7),
                }),
            ] {
                let pa = at(x, y, 1.0 + gap);
                let r = closest_features(&a, &pa, &b, &at(0.0, 0.0, 0.0), start);
                assert!(!r.penetrating);
                assert!((r.distance - gap).abs() < 1e-12, "{x} {y} {gap}: {r:?}");
            }
        }
    }
}

/// Parallel edges: two cubes turned 45° about x, edge above edge.
#[test]
fn parallel_edges_give_the_gap() {
    let a = cuboid(0.5, 0.5, 0.5);
    let turn = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_4);
    let h = 0.5 * 2f64.sqrt();
    for gap in [0.0, 1e-6, 0.2] {
        for shift in [0.0, 0.6, 0.99] {
            let r = closest_features(
                &a,
                &pose(v(shift, 0.0, 2.0 * h + gap), turn),
                &a,
                &pose(v(0.0, 0.0, 0.0), turn),
                None,
            );
            assert!((r.distance - gap).abs() < 1e-12, "{gap} {shift}: {r:?}");
        }
    }
}

/// A cube balanced on a corner over a face, touching and just above.
#[test]
fn vertex_on_face() {
    let a = cuboid(0.5, 0.5, 0.5);
    let floor = cuboid(3.0, 3.0, 0.5);
    // Rotate the (-,-,-) corner to point straight down.
    let down = UnitQuaternion::rotation_between(&v(-1.0, -1.0, -1.0), &v(0.0, 0.0, -1.0)).unwrap();
    let h = 0.5 * 3f64.sqrt();
    for gap in [0.0, 1e-10, 0.05] {
        let r = closest_features(
            &a,
            &pose(v(0.2, -0.1, 0.5 + h + gap), down),
            &floor,
            &at(0.0, 0.0, 0.0),
            None,
        );
        assert!((r.distance - gap).abs() < 1e-12, "{gap}: {r:?}");
        if gap > 0.0 {
            assert!(
                matches!(
                    r.features,
                    FeaturePair {
                        a: Feature::Vertex(_),
                        b: Feature::Face(_)
                    }
                ),
                "{r:?}"
            );
        }
    }
}

/// Two cubes meeting corner to corner along their diagonal.
#[test]
fn touching_at_a_single_point() {
    let a = cuboid(0.5, 0.5, 0.5);
    let r = closest_features(&a, &at(1.0, 1.0, 1.0), &a, &at(0.0, 0.0, 0.0), None);
    assert_eq!(r.distance, 0.0);
    assert!((r.point_a - v(0.5, 0.5, 0.5)).norm() < 1e-15);
    let r = closest_features(&a, &at(1.1, 1.1, 1.1), &a, &at(0.0, 0.0, 0.0), None);
    assert!((r.distance - 0.1 * 3f64.sqrt()).abs() < 1e-14);
    let corner = |x: Vector3<f64>| {
        Feature::Vertex(a.vertices().iter().position(|p| *p == x).unwrap() as u32)
    };
    assert_eq!(
        r.features,
        FeaturePair {
            a: corner(v(-0.5, -0.5, -0.5)),
            b: corner(v(0.5, 0.5, 0.5))
        }
    );
}

/// Identical polyhedra at the same pose, and one swallowed by another.
#[test]
fn identical_and_nested_polyhedra_penetrate() {
    let shapes = [cuboid(0.5, 0.5, 0.5), prism(9, 0.5, 0.2), geodesic(80, 0.7)];
    for s in &shapes {
        let p = pose(
            v(0.3, -1.0, 2.0),
            UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
        );
        let r = closest_features(s, &p, s, &p, None);
        assert!(r.penetrating && r.distance <= 0.0, "{r:?}");
    }
    let big = cuboid(2.0, 2.0, 2.0);
    let small = geodesic(40, 0.3);
    let r = closest_features(&small, &at(0.1, 0.2, 0.3), &big, &at(0.0, 0.0, 0.0), None);
    assert!(r.penetrating);
    let r = closest_features(&big, &at(0.0, 0.0, 0.0), &small, &at(0.1, 0.2, 0.3), None);
    assert!(r.penetrating);
}

/// Every feature pair of A and B as a warm start converges, without the
/// fallback, to the cold answer.
fn assert_every_warm_start_agrees(
    a: &ConvexPolyhedron,
    pa: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pb: &Isometry3<f64>,
) {
    let features = |p: &ConvexPolyhedron| -> Vec<Feature> {
        (0..p.vertices().len() as u32)
            .map(Feature::Vertex)
            .chain((0..p.edges().len() as u32).map(Feature::Edge))
            .chain((0..p.face_count() as u32).map(Feature::Face))
            .collect()
    };
    let truth = exhaustive(a, pa, b, pb);
    let size = a.scale().max(b.scale());
    for fa in features(a) {
        for fb in features(b) {
            let r = closest_features(a, pa, b, pb, Some(FeaturePair { a: fa, b: fb }));
            assert!(!r.fell_back, "from {fa:?} {fb:?}: {r:?}");
            if truth.distance.abs() > 1e-9 * size {
                assert_eq!(
                    r.penetrating, truth.penetrating,
                    "from {fa:?} {fb:?}: {r:?}"
                );
            }
            if !r.penetrating {
                assert!(
                    (r.distance - truth.distance).abs() <= 1e-12 * size,
                    "from {fa:?} {fb:?}: {r:?} vs {truth:?}"
                );
            }
        }
    }
}

fn euler(r: f64, p: f64, y: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(r, p, y)
}

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// A box edge 7 mm under a triangular prism's horizontal bottom face, and
/// crossing under one of its edges: the distance derivative where the edge
/// leaves the face's prism is exactly 0 and its rounded sign used to bounce
/// the walk between the face and that edge.
#[test]
fn edge_parallel_under_a_face_does_not_cycle() {
    let a = cuboid(1.0, 0.25, 0.5);
    let b = prism(3, 0.7, 0.2);
    let pa = pose(v(0.5, -1.0, 1e-6), euler(PI, 0.0, -FRAC_PI_4));
    let pb = pose(v(0.25, -1.0, FRAC_PI_4.sin()), euler(PI, PI, PI));
    assert_every_warm_start_agrees(&a, &pa, &b, &pb);
}

/// An edge passing exactly through another edge's line: both derivatives
/// vanish and the edge is clipped out of the other's region by rounding.
#[test]
fn edge_through_another_edge_does_not_cycle() {
    let a = prism(4, 0.5, 0.5);
    let b = cuboid(0.5, 0.5, 0.5);
    let s = FRAC_PI_4.sin();
    let pa = pose(v(0.5, s, s + 1e-6), euler(0.0, FRAC_PI_2, -FRAC_PI_4));
    let pb = pose(v(-0.5, 1.0, 0.25), euler(-FRAC_PI_4, FRAC_PI_4, -FRAC_PI_4));
    assert_every_warm_start_agrees(&a, &pa, &b, &pb);
}

/// Overlapping cubes, one turned 45°, where an edge of one lies in a
/// Voronoi plane of the other: its ends straddle the plane by rounding and
/// used to be clipped at an arbitrary point.
#[test]
fn edge_lying_in_a_voronoi_plane_does_not_cycle() {
    let a = cuboid(0.5, 0.5, 0.5);
    let s = FRAC_PI_4.sin();
    let pa = pose(v(0.0, s, s + 0.1), euler(0.0, FRAC_PI_2, -FRAC_PI_4));
    let pb = pose(v(0.0, 1.0, 0.5), euler(PI, PI, PI));
    assert_every_warm_start_agrees(&a, &pa, &a, &pb);
}

/// A vertex on the rim of a face's prism, under the face, with an edge that
/// rises out of the prism: the clipped edge has zero length, and the walk
/// must follow the edge's slope rather than fall back to the vertex. B is a
/// tetrahedron touching A's x = 0.5 side with its apex.
#[test]
fn vertex_on_a_prism_rim_below_the_face_does_not_cycle() {
    let a = cuboid(0.5, 2.0, 0.5);
    for rise in [0.5, 0.1, -0.2] {
        let b = ConvexPolyhedron::hull(&[
            v(0.0, 0.0, 0.0),
            v(1.0, 0.0, rise),
            v(0.3, 1.0, -0.4),
            v(0.3, -1.0, -0.4),
        ])
        .unwrap();
        for z in [0.2, 0.0, -0.3] {
            let pb = at(0.5, 0.1, z);
            assert_every_warm_start_agrees(&a, &at(0.0, 0.0, 0.0), &b, &pb);
            let r = closest_features(&a, &at(0.0, 0.0, 0.0), &b, &pb, None);
            assert!(r.distance.abs() < 1e-15, "{r:?}");
        }
    }
}

/// Boxes and prisms in right-angle and 45° poses on a coarse grid, with
/// gaps of 0, 1e-12, 1e-6, 0.1 and -1e-9: the configurations where V-Clip's
/// exact-zero tie-breaks matter. No fallback, and the same answer as the
/// exhaustive search (1e-9 absolute; bodies are about 1 m).
#[test]
fn right_angle_poses_agree_with_exhaustive_search() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let shapes = [
        cuboid(0.5, 0.5, 0.5),
        cuboid(1.0, 0.25, 0.5),
        prism(4, 0.5, 0.5),
        prism(6, 0.5, 0.3),
        prism(3, 0.7, 0.2),
        cuboid(3.0, 3.0, 0.5),
    ];
    let angles = [0.0, FRAC_PI_4, FRAC_PI_2, PI, -FRAC_PI_4];
    let grid = [0.0, 0.25, 0.5, 1.0, -0.5, -1.0, FRAC_PI_4.sin(), 1.5];
    let mut max_iterations = 0;
    for case in 0..4000 {
        let a = &shapes[rng.random_range(0..shapes.len())];
        let b = &shapes[rng.random_range(0..shapes.len())];
        let gap = [0.0, 1e-12, 1e-6, 0.1, -1e-9][rng.random_range(0..5)];
        let mut place = |dz: f64| {
            let t = v(
                grid[rng.random_range(0..8)],
                grid[rng.random_range(0..8)],
                grid[rng.random_range(0..8)] + dz,
            );
            let r = euler(
                angles[rng.random_range(0..5)],
                angles[rng.random_range(0..5)],
                angles[rng.random_range(0..5)],
            );
            pose(t, r)
        };
        let pa = place(gap);
        let pb = place(0.0);
        let r = closest_features(a, &pa, b, &pb, None);
        let x = exhaustive(a, &pa, b, &pb);
        max_iterations = max_iterations.max(r.iterations);
        assert!(!r.fell_back, "case {case}");
        if x.distance.abs() > 1e-9 {
            assert_eq!(r.penetrating, x.penetrating, "case {case}: {r:?} {x:?}");
            if !r.penetrating {
                assert!(
                    (r.distance - x.distance).abs() < 1e-12,
                    "case {case}: {r:?} {x:?}"
                );
            }
        } else {
            assert!(
                r.penetrating || r.distance < 1e-9,
                "case {case}: {r:?} {x:?}"
            );
        }
        let contacts = contact_points(a, &pa, b, &pb, &r, TOL);
        if r.penetrating || r.distance <= TOL {
            assert!(!contacts.is_empty(), "case {case}");
        }
    }
    println!("max iterations {max_iterations}");
}

/// Random shapes (geodesic spheres, many-sided prisms, random hulls) put at
/// an exact gap along an axis or a random direction: touching, 1e-12 and
/// 1e-7 apart or overlapping, 0.01 apart. Half the queries are warm-started
/// from the previous (unrelated) pair's features.
#[test]
fn exact_contacts_agree_with_exhaustive_search() {
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let mut shapes = vec![
        cuboid(0.5, 0.5, 0.5),
        cuboid(2.0, 2.0, 0.1),
        prism(8, 0.5, 0.5),
        prism(50, 0.5, 0.2),
        geodesic(60, 0.5),
        geodesic(30, 0.3),
    ];
    for _ in 0..4 {
        let pts: Vec<_> = (0..20)
            .map(|_| {
                v(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                )
            })
            .collect();
        shapes.push(ConvexPolyhedron::hull(&pts).unwrap());
    }
    let mut warm = None;
    for case in 0..400 {
        let a = &shapes[rng.random_range(0..shapes.len())];
        let b = &shapes[rng.random_range(0..shapes.len())];
        let mut rot = || {
            if rng.random_bool(0.5) {
                let q = [0.0, FRAC_PI_2, PI];
                euler(
                    q[rng.random_range(0..3)],
                    q[rng.random_range(0..3)],
                    q[rng.random_range(0..3)],
                )
            } else {
                random_rotation(&mut rng)
            }
        };
        let (ra, rb) = (rot(), rot());
        let dir = if rng.random_bool(0.5) {
            [Vector3::x(), -Vector3::y(), Vector3::z()][rng.random_range(0..3)]
        } else {
            random_direction(&mut rng)
        };
        let gap = [0.0, 1e-12, -1e-12, 1e-7, -1e-7, 0.01][rng.random_range(0..6)];
        let pa = pose(v(0.3, -0.2, 0.1), ra);
        // B's support plane along -dir sits `gap` beyond A's along dir.
        let ha = (pa * nalgebra::Point3::from(a.support(&(ra.inverse() * dir))))
            .coords
            .dot(&dir);
        let hb = (rb * b.support(&(rb.inverse() * -dir))).dot(&dir);
        let side = v(
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.3..0.3),
        );
        let pb = pose(dir * (ha - hb + gap) + side - dir * side.dot(&dir), rb);
        let r = closest_features(
            a,
            &pa,
            b,
            &pb,
            if rng.random_bool(0.5) { warm } else { None },
        );
        warm = Some(r.features);
        let x = exhaustive(a, &pa, b, &pb);
        assert!(!r.fell_back, "case {case}");
        if x.distance.abs() > 1e-9 {
            assert_eq!(r.penetrating, x.penetrating, "case {case}: {r:?} {x:?}");
            if !r.penetrating {
                assert!(
                    (r.distance - x.distance).abs() < 1e-12,
                    "case {case}: {r:?} {x:?}"
                );
            }
        } else {
            assert!(
                r.penetrating || r.distance < 1e-9,
                "case {case}: {r:?} {x:?}"
            );
        }
        let contacts = contact_points(a, &pa, b, &pb, &r, TOL);
        if r.penetrating || r.distance <= TOL {
            assert!(!contacts.is_empty(), "case {case}");
            for c in &contacts {
                assert!(
                    (c.normal.norm() - 1.0).abs() < 1e-12 && c.separation < TOL + 1e-12,
                    "case {case}: {c:?}"
                );
            }
        }
    }
}

// ---------------------------------------------------------------- construction

#[test]
fn cube_from_twelve_triangles_merges_to_six_quads() {
    let (verts, tris) = cube_triangles();
    let p = ConvexPolyhedron::from_faces(verts, tris).unwrap();
    assert_eq!(p.face_count(), 6);
    assert_eq!(p.edges().len(), 12);
    assert_eq!(p.vertices().len(), 8);
    assert!(p.faces().iter().all(|f| f.vertices.len() == 4));
    for f in p.faces() {
        for &i in &f.vertices {
            assert!((f.normal.dot(&p.vertices()[i]) - f.offset).abs() < 1e-15);
        }
        assert!((f.offset - 0.5).abs() < 1e-15);
    }
    assert_eq!(p.triangles().len(), 12);
}

#[test]
fn collinear_and_interior_vertices_of_merged_faces_are_dropped() {
    // A cube whose top face is split through an extra vertex in its middle
    // and one on an edge midpoint: 8 corners survive.
    let (mut verts, mut quads) = cuboid_mesh(0.5, 0.5, 0.5);
    verts.push(v(0.0, 0.0, 0.5)); // 8: top centre
    verts.push(v(0.5, 0.0, 0.5)); // 9: midpoint of top edge 5-7
    quads[1] = vec![4, 5, 8];
    quads.push(vec![5, 9, 8]);
    quads.push(vec![9, 7, 8]);
    quads.push(vec![7, 6, 8]);
    quads.push(vec![6, 4, 8]);
    quads[5] = vec![1, 3, 7, 9, 5]; // x = +0.5 face now runs through 9
    let p = ConvexPolyhedron::from_faces(verts, quads).unwrap();
    assert_eq!(
        (p.vertices().len(), p.edges().len(), p.face_count()),
        (8, 12, 6)
    );
}

#[test]
fn triangle_soup_works_after_welding() {
    let (verts, tris) = cube_triangles();
    let mut soup_v = Vec::new();
    let mut soup_f = Vec::new();
    for t in &tris {
        soup_f.push((0..3).map(|k| soup_v.len() + k).collect());
        soup_v.extend(t.iter().map(|&i| verts[i]));
    }
    assert!(matches!(
        ConvexPolyhedron::from_faces(soup_v.clone(), soup_f.clone()),
        Err(PolyhedronError::OpenEdge { .. })
    ));
    let (wv, wf) = weld(&soup_v, &soup_f, 1e-9);
    let p = ConvexPolyhedron::from_faces(wv, wf).unwrap();
    assert_eq!((p.vertices().len(), p.face_count()), (8, 6));
}

#[test]
fn l_shaped_prism_is_rejected_as_not_convex() {
    // L-shaped cross-section in xy, extruded along z.
    let outline = [
        v(0.0, 0.0, 0.0),
        v(2.0, 0.0, 0.0),
        v(2.0, 1.0, 0.0),
        v(1.0, 1.0, 0.0),
        v(1.0, 2.0, 0.0),
        v(0.0, 2.0, 0.0),
    ];
    let n = outline.len();
    let mut verts: Vec<_> = outline.to_vec();
    verts.extend(outline.iter().map(|p| p + v(0.0, 0.0, 1.0)));
    let mut faces = vec![(0..n).rev().collect::<Vec<_>>(), (n..2 * n).collect()];
    for k in 0..n {
        faces.push(vec![k, (k + 1) % n, n + (k + 1) % n, n + k]);
    }
    let err = ConvexPolyhedron::from_faces(verts, faces).unwrap_err();
    let PolyhedronError::NotConvex {
        vertex,
        face,
        distance,
    } = err
    else {
        panic!("{err:?}");
    };
    // The worst offenders lie 1 m outside a face at the notch: the corners
    // at y = 2 outside face 4 (y = 1, x ∈ [1, 2]), or those at x = 2
    // outside face 5 (x = 1, y ∈ [1, 2]).
    assert!((distance - 1.0).abs() < 1e-12);
    let outside_4 = [4, 5, 10, 11].contains(&vertex) && face == 4;
    let outside_5 = [1, 2, 7, 8].contains(&vertex) && face == 5;
    assert!(outside_4 || outside_5, "{vertex} {face}");
    let msg = format!("part 'bracket': {err}");
    assert_eq!(
        msg,
        format!("part 'bracket': is not convex: vertex {vertex} lies 1.0000 m outside face {face}")
    );
}

#[test]
fn cube_with_a_dented_corner_is_rejected_naming_vertex_and_face() {
    let (mut verts, tris) = cube_triangles();
    verts[7] = v(0.1, 0.1, 0.1);
    let err = ConvexPolyhedron::from_faces(verts, tris).unwrap_err();
    assert!(matches!(err, PolyhedronError::NotConvex { .. }), "{err:?}");
    assert!(
        err.to_string().starts_with("is not convex: vertex "),
        "{err}"
    );
}

#[test]
fn open_inward_flat_and_inconsistent_meshes_are_rejected() {
    let (verts, mut tris) = cube_triangles();
    let full = tris.clone();
    tris.pop();
    let err = ConvexPolyhedron::from_faces(verts.clone(), tris).unwrap_err();
    assert!(matches!(err, PolyhedronError::OpenEdge { .. }), "{err:?}");
    assert!(err.to_string().starts_with("is not closed"));

    let inward: Vec<Vec<usize>> = full
        .iter()
        .map(|t| t.iter().rev().copied().collect())
        .collect();
    let err = ConvexPolyhedron::from_faces(verts.clone(), inward).unwrap_err();
    assert!(
        matches!(err, PolyhedronError::InwardWinding { .. }),
        "{err:?}"
    );

    let flat = vec![v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(0.0, 1.0, 0.0)];
    let err = ConvexPolyhedron::from_faces(flat, vec![vec![0, 1, 2], vec![0, 2, 1]]).unwrap_err();
    assert!(matches!(err, PolyhedronError::ZeroVolume { .. }), "{err:?}");

    let mut flipped = full.clone();
    flipped[3].reverse();
    let err = ConvexPolyhedron::from_faces(verts.clone(), flipped).unwrap_err();
    assert!(
        matches!(err, PolyhedronError::InconsistentWinding { .. }),
        "{err:?}"
    );

    let mut bad = full.clone();
    bad[0] = vec![0, 1];
    assert!(matches!(
        ConvexPolyhedron::from_faces(verts.clone(), bad),
        Err(PolyhedronError::TooFewFaceVertices { face: 0, count: 2 })
    ));
    let mut bad = full;
    bad[2][1] = 42;
    assert!(matches!(
        ConvexPolyhedron::from_faces(verts.clone(), bad),
        Err(PolyhedronError::IndexOutOfRange { index: 42, .. })
    ));
    let mut nan = verts;
    nan[3].y = f64::NAN;
    assert!(matches!(
        ConvexPolyhedron::from_faces(nan, cube_triangles().1),
        Err(PolyhedronError::NonFinite { vertex: 3 })
    ));
}

#[test]
fn hull_contains_its_points_and_is_convex() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for n in [4, 5, 10, 50, 300] {
        for _ in 0..10 {
            let pts: Vec<_> = (0..n)
                .map(|_| {
                    v(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-2.0..2.0),
                        rng.random_range(-0.5..0.5),
                    )
                })
                .collect();
            let p = ConvexPolyhedron::hull(&pts).unwrap();
            let tol = 1e-9 * p.scale();
            for x in &pts {
                assert!(outside(&p, &Isometry3::identity(), x) <= tol);
            }
            for f in p.faces() {
                for x in p.vertices() {
                    assert!(f.normal.dot(x) - f.offset <= tol);
                }
            }
            for e in p.edges() {
                // Convex dihedral: the right face's far vertices lie under the left plane.
                let nl = p.faces()[e.left as usize].normal;
                let nr = p.faces()[e.right as usize].normal;
                assert!(
                    nl.cross(&nr)
                        .dot(&p.edge_direction(p.edges().iter().position(|x| x == e).unwrap()))
                        > 0.0
                );
            }
            let euler = p.vertices().len() as i64 - p.edges().len() as i64 + p.face_count() as i64;
            assert_eq!(euler, 2);
        }
    }
}

#[test]
fn hull_merges_coplanar_points_and_rejects_flat_input() {
    // Box corners plus points on its faces and inside: 6 faces.
    let mut pts: Vec<_> = cuboid_mesh(1.0, 0.5, 0.25).0;
    pts.extend([
        v(0.0, 0.0, 0.25),
        v(1.0, 0.1, 0.0),
        v(0.2, -0.5, 0.1),
        v(0.0, 0.0, 0.0),
        v(0.5, 0.5, 0.25),
    ]);
    let p = ConvexPolyhedron::hull(&pts).unwrap();
    assert_eq!((p.vertices().len(), p.face_count()), (8, 6));

    let err = ConvexPolyhedron::hull(&[v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(0.0, 1.0, 0.0)])
        .unwrap_err();
    assert_eq!(err, PolyhedronError::TooFewPoints { count: 3 });
    let flat: Vec<_> = (0..10).map(|i| v(i as f64, (i * i) as f64, 0.0)).collect();
    assert_eq!(
        ConvexPolyhedron::hull(&flat).unwrap_err(),
        PolyhedronError::DegenerateHull { shape: "coplanar" }
    );
    let line: Vec<_> = (0..10).map(|i| v(i as f64, 2.0 * i as f64, 0.0)).collect();
    assert_eq!(
        ConvexPolyhedron::hull(&line).unwrap_err(),
        PolyhedronError::DegenerateHull { shape: "collinear" }
    );
}

/// Points on a 5×5×5 lattice (every face full of coplanar and collinear
/// points) and on a sphere (all cospherical): the hull is still exact.
#[test]
fn hull_of_lattice_and_cospherical_points() {
    let lattice: Vec<_> = (0..125)
        .map(|i| {
            v(
                (i % 5) as f64 * 0.25,
                (i / 5 % 5) as f64 * 0.25,
                (i / 25) as f64 * 0.25,
            )
        })
        .collect();
    let p = ConvexPolyhedron::hull(&lattice).unwrap();
    assert_eq!(
        (p.vertices().len(), p.edges().len(), p.face_count()),
        (8, 12, 6)
    );
    // A cube lattice seen from a skew frame: same answer.
    let turn = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.1);
    let turned: Vec<_> = lattice
        .iter()
        .map(|x| turn * x + v(10.0, -3.0, 2.0))
        .collect();
    let p = ConvexPolyhedron::hull(&turned).unwrap();
    assert_eq!((p.vertices().len(), p.face_count()), (8, 6));
    // An octahedron's 6 vertices plus the midpoints of its edges.
    let mut octa = vec![
        v(1.0, 0.0, 0.0),
        v(-1.0, 0.0, 0.0),
        v(0.0, 1.0, 0.0),
        v(0.0, -1.0, 0.0),
        v(0.0, 0.0, 1.0),
        v(0.0, 0.0, -1.0),
    ];
    for i in 0..6 {
        for j in i + 1..6 {
            if (octa[i] + octa[j]).norm() > 0.5 {
                octa.push((octa[i] + octa[j]) / 2.0);
            }
        }
    }
    let p = ConvexPolyhedron::hull(&octa).unwrap();
    assert_eq!((p.vertices().len(), p.face_count()), (6, 8));
    let g = geodesic(500, 1.0);
    assert_eq!(g.face_count(), 996);
}

/// Near-duplicate, nearly coplanar, tiny and far-off point sets: `hull`
/// either builds a valid polyhedron holding every point or reports an
/// error; it never panics.
#[test]
fn hull_survives_nasty_point_sets() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let (mut built, mut refused) = (0, 0);
    for _ in 0..400 {
        let scale = [1e-6, 1.0, 1e3][rng.random_range(0..3)];
        let offset = v(1.0, -2.0, 0.5) * [0.0, 1.0, 1e6][rng.random_range(0..3)];
        let flat = [1.0, 1e-3, 1e-10, 0.0][rng.random_range(0..4)];
        let mut pts: Vec<_> = (0..rng.random_range(4..30))
            .map(|_| {
                v(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    flat * rng.random_range(-1.0..1.0),
                )
            })
            .collect();
        // Near-duplicates of some points.
        for _ in 0..rng.random_range(0..10) {
            let p = pts[rng.random_range(0..pts.len())];
            let jitter = [0.0, 1e-14, 1e-9, 1e-6][rng.random_range(0..4)];
            pts.push(p + random_direction(&mut rng) * jitter);
        }
        let pts: Vec<_> = pts.iter().map(|p| p * scale + offset).collect();
        match ConvexPolyhedron::hull(&pts) {
            Ok(p) => {
                built += 1;
                // HULL_MERGE_REL_TOL of the size, or 64 ulps of far-off coordinates.
                let coordinate_ulp = f64::EPSILON * (offset.norm() + scale);
                let tol = 1e-8 * p.scale() + 128.0 * coordinate_ulp;
                for x in &pts {
                    let o = outside(&p, &Isometry3::identity(), x);
                    assert!(
                        o <= tol,
                        "outside by {o:e} (tol {tol:e}), scale {scale} offset {offset:?} flat {flat}, size {}",
                        p.scale()
                    );
                }
            }
            Err(e) => {
                refused += 1;
                // Only sets flat to within the coordinates' rounding may be refused.
                let thickness = flat * scale;
                let coordinate_ulp = f64::EPSILON * (offset.norm() + scale);
                assert!(
                    flat <= 1e-10 || thickness < 1e3 * coordinate_ulp,
                    "{e} (flat {flat}, scale {scale})"
                );
            }
        }
    }
    println!("built {built}, refused {refused}");
    assert!(built > 200);
}

#[test]
fn geodesic_sphere_has_two_hundred_triangles() {
    let g = geodesic(102, 1.0);
    assert_eq!(g.face_count(), 200);
    let (c, r) = g.bounding_sphere();
    assert!(c.norm() < 0.05 && (r - 1.0).abs() < 0.05);
}

// ---------------------------------------------------------------- manifold

const TOL: f64 = 1e-4;

fn contacts(
    a: &ConvexPolyhedron,
    pa: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pb: &Isometry3<f64>,
) -> Vec<ContactPoint> {
    let prox = closest_features(a, pa, b, pb, None);
    contact_points(a, pa, b, pb, &prox, TOL)
}

fn assert_points(got: &[ContactPoint], want: &[Vector3<f64>], normal: Vector3<f64>, sep: f64) {
    assert_eq!(got.len(), want.len(), "{got:#?}");
    for w in want {
        let c = got
            .iter()
            .find(|c| (c.point - w).norm() < 1e-9)
            .unwrap_or_else(|| panic!("no point at {w:?} in {got:#?}"));
        assert!((c.normal - normal).norm() < 1e-12, "{c:?}");
        assert!((c.separation - sep).abs() < 1e-12, "{c:?}");
    }
}

/// Floor: 10 × 10 × 1 m box whose top face is z = 0.
fn floor() -> (ConvexPolyhedron, Isometry3<f64>) {
    (cuboid(5.0, 5.0, 0.5), at(0.0, 0.0, -0.5))
}

#[test]
fn box_resting_flat_gives_its_four_corners() {
    let (fl, pf) = floor();
    let a = cuboid(0.5, 0.5, 0.5);
    let corners = [
        v(0.5, 0.5, 0.0),
        v(-0.5, 0.5, 0.0),
        v(0.5, -0.5, 0.0),
        v(-0.5, -0.5, 0.0),
    ];
    for gap in [0.0, 5e-5, -1e-7] {
        let got = contacts(&a, &at(0.0, 0.0, 0.5 + gap), &fl, &pf);
        let want: Vec<_> = corners.iter().map(|c| c + v(0.0, 0.0, gap / 2.0)).collect();
        assert_points(&got, &want, Vector3::z(), gap);
        // Swapping the bodies flips the normal (out of B towards A).
        let got = contacts(&fl, &pf, &a, &at(0.0, 0.0, 0.5 + gap));
        assert_points(&got, &want, -Vector3::z(), gap);
    }
    assert!(contacts(&a, &at(0.0, 0.0, 0.5 + 2.0 * TOL), &fl, &pf).is_empty());
}

#[test]
fn box_resting_flat_within_the_face_angle_still_gives_four_corners() {
    let (fl, pf) = floor();
    let a = cuboid(0.5, 0.5, 0.5);
    // Tilted by 1e-5 rad: the far edge gapes 1e-5 m < TOL.
    let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 1e-5);
    let low = (tilt * v(0.5, -0.5, -0.5))
        .z
        .min((tilt * v(0.5, 0.5, -0.5)).z);
    let got = contacts(&a, &pose(v(0.0, 0.0, -low), tilt), &fl, &pf);
    assert_eq!(got.len(), 4, "{got:#?}");
    // Tilted by 5e-3 rad (inside the face angle): the far edge gapes 5 mm and
    // is dropped, leaving the touching edge.
    let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 5e-3);
    let low = (tilt * v(0.5, -0.5, -0.5))
        .z
        .min((tilt * v(0.5, 0.5, -0.5)).z);
    let got = contacts(&a, &pose(v(0.0, 0.0, -low), tilt), &fl, &pf);
    assert_eq!(got.len(), 2, "{got:#?}");
}

#[test]
fn box_on_its_edge_gives_two_points() {
    let (fl, pf) = floor();
    let a = cuboid(0.5, 0.5, 0.5);
    let turn = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_4);
    let h = 0.5 * 2f64.sqrt();
    for gap in [0.0, 3e-5, -2e-7] {
        let got = contacts(&a, &pose(v(0.3, 0.0, h + gap), turn), &fl, &pf);
        assert_points(
            &got,
            &[v(0.8, 0.0, gap / 2.0), v(-0.2, 0.0, gap / 2.0)],
            Vector3::z(),
            gap,
        );
    }
}

#[test]
fn box_on_a_corner_gives_one_point() {
    let (fl, pf) = floor();
    let a = cuboid(0.5, 0.5, 0.5);
    let tilt = UnitQuaternion::from_euler_angles(0.5, 0.3, 0.2);
    let lowest = a
        .vertices()
        .iter()
        .map(|x| tilt * x)
        .min_by(|p, q| p.z.total_cmp(&q.z))
        .unwrap();
    for gap in [0.0, 5e-5, -1e-7] {
        let c = v(0.1, 0.2, -lowest.z + gap);
        let got = contacts(&a, &pose(c, tilt), &fl, &pf);
        let want = c + lowest - v(0.0, 0.0, gap / 2.0);
        assert_points(&got, &[want], Vector3::z(), gap);
    }
}

#[test]
fn box_on_a_larger_box_off_centre_gives_the_overlap_rectangle() {
    let big = cuboid(2.0, 2.0, 0.5);
    let a = cuboid(0.5, 0.5, 0.5);
    // A spans x ∈ [1.2, 2.2], y ∈ [-0.2, 0.8]; B's top spans [-2, 2]².
    for gap in [0.0, -1e-8] {
        let got = contacts(&a, &at(1.7, 0.3, 1.0 + gap), &big, &at(0.0, 0.0, 0.0));
        let z = 0.5 + gap / 2.0;
        assert_points(
            &got,
            &[
                v(1.2, -0.2, z),
                v(2.0, -0.2, z),
                v(2.0, 0.8, z),
                v(1.2, 0.8, z),
            ],
            Vector3::z(),
            gap,
        );
    }
}

#[test]
fn crossed_edges_give_one_point_and_parallel_edges_two() {
    let a = cuboid(0.5, 0.5, 0.5);
    let about_x = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_4);
    let about_y = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_4);
    let h = 0.5 * 2f64.sqrt();
    // A's lowest edge along x crosses B's highest edge along y.
    let got = contacts(
        &a,
        &pose(v(0.0, 0.0, 2.0 * h), about_x),
        &a,
        &pose(v(0.0, 0.0, 0.0), about_y),
    );
    assert_points(&got, &[v(0.0, 0.0, h)], Vector3::z(), 0.0);
    // Both along x, A shifted by 0.4 m: the common stretch x ∈ [-0.1, 0.5].
    let got = contacts(
        &a,
        &pose(v(0.4, 0.0, 2.0 * h), about_x),
        &a,
        &pose(v(0.0, 0.0, 0.0), about_x),
    );
    assert_points(&got, &[v(-0.1, 0.0, h), v(0.5, 0.0, h)], Vector3::z(), 0.0);
}

/// Random sweep seed 5, scene 74, t = 1.3164 s: a box (A) and a hull (B)
/// both resting on the floor, the box's bottom edge nearly crossing the
/// hull's, world coordinates. They overlap by 0.750 µm (the hull of A − B,
/// checked with qhull; parry agrees below); V-Clip, warm-started from the
/// previous step's features, ended on features 1.7e-12 m apart and called
/// them apart, so the contact missed the overlap and the pair sank 11.8 µm
/// (docs/stability.md, *Regression scenes*). From any starting feature pair V-Clip
/// must now find the overlap, and the separating-axis test must choose the
/// 0.750 µm axis across the edges over the hull's face 15° away (0.776 µm).
#[test]
fn box_and_hull_meeting_on_a_floor_overlap_from_every_warm_start() {
    let a = ConvexPolyhedron::hull(&[
        v(
            -0.32813916823655875,
            0.15365449689689556,
            1.5067541424704234e-05,
        ),
        v(
            -0.32812590993600255,
            0.15366591978992614,
            0.09600799734961686,
        ),
        v(-0.414694539877879, 0.2808471643602855, 0.09600481977353584),
        v(
            -0.4147077981784353,
            0.280835741467255,
            1.188996534368103e-05,
        ),
        v(
            -0.27392241228067205,
            0.1905606876323989,
            0.09599612052439813,
        ),
        v(
            -0.2739356705812283,
            0.1905492647393683,
            3.190716205969668e-06,
        ),
        v(
            -0.3605043005231048,
            0.3177305093097277,
            1.314012494646466e-08,
        ),
        v(-0.3604910422225486, 0.31774193220275826, 0.0959929429483171),
    ])
    .unwrap();
    let b = ConvexPolyhedron::hull(&[
        v(
            -0.27113495281713196,
            0.1864607260530993,
            -6.073900811962019e-07,
        ),
        v(
            -0.3855114283550007,
            0.3544604165025387,
            4.4163948254710705e-07,
        ),
        v(
            -0.25038483211919477,
            0.3824990178393239,
            1.753194203395203e-05,
        ),
        v(
            -0.36926174727440986,
            0.36926565879715867,
            0.08199690535577514,
        ),
        v(-0.21830930929510906, 0.2215319258947248, 0.0809220332755189),
        v(
            -0.21630964345170894,
            0.31980375423315743,
            0.0944202468294979,
        ),
        v(
            -0.18407216251512856,
            0.3014179364429333,
            0.007212020307909885,
        ),
        v(-0.24239614799086104, 0.4121348476630294, 0.0925099982903905),
        v(
            -0.25645741540888833,
            0.4006284922912962,
            0.011435161911195861,
        ),
        v(
            -0.29313592064282035,
            0.27964621215420177,
            0.07126599977349551,
        ),
        v(
            -0.20209808185855943,
            0.38647492936170047,
            0.05025797209352773,
        ),
    ])
    .unwrap();
    let id = Isometry3::identity();
    let (_, signed) = Oracle::new(&a, &b).query(&id, &id);
    assert!(signed < -7e-7, "parry: {signed:e}");
    let sat = separating_axis(&a, &id, &b, &id);
    assert!(
        (sat.separation + 7.5e-7).abs() < 1e-9,
        "separating axis {:e} along {:?}",
        sat.separation,
        sat.normal
    );
    let truth = exhaustive(&a, &id, &b, &id);
    assert!(truth.penetrating, "{truth:?}");
    assert_every_warm_start_agrees(&a, &id, &b, &id);
}

/// Random sweep seed 4, scene 113 (with impacts of touching pairs bisected
/// on depth alone): two hulls, world coordinates, overlapping by 0.339 mm
/// across two edges (the hull of A − B, checked with qhull). The axis is
/// the edges' and reproduces a face normal, so each body offered the face
/// along it, and the faces' clipped points were 13.7 µm apart: the overlap
/// went unseen until it jumped into view 0.48 mm deep. The contact points
/// must hold the overlap along their normal.
#[test]
fn contact_points_hold_an_overlap_of_edges_crossing_beside_faces() {
    let a = ConvexPolyhedron::hull(&[
        v(
            -0.41691499428379175,
            -0.5101429945578411,
            0.08599531882416885,
        ),
        v(
            -0.5034331547789995,
            -0.41372067798018697,
            0.08599503498870575,
        ),
        v(
            -0.5998554713164481,
            -0.5002388384274996,
            0.08599905015793771,
        ),
        v(
            -0.5133373108212403,
            -0.5966611550051537,
            0.08599933399340082,
        ),
        v(
            -0.513339168697471,
            -0.5966630751776243,
            7.810360583684894e-06,
        ),
        v(
            -0.5998573291926788,
            -0.5002407585999702,
            7.526525120593597e-06,
        ),
        v(
            -0.5034350126552302,
            -0.41372259815265755,
            3.5113558886218366e-06,
        ),
        v(
            -0.41691685216002244,
            -0.5101449147303116,
            3.795191351727012e-06,
        ),
    ])
    .unwrap();
    let b = ConvexPolyhedron::hull(&[
        v(
            -0.41079928709192054,
            -0.4913716642672826,
            0.1610961861018448,
        ),
        v(-0.31426485101292, -0.4453487775214944, 0.23087982767869622),
        v(
            -0.4149249892459643,
            -0.3715889240168219,
            0.19240249463533332,
        ),
        v(
            -0.49504308770902516,
            -0.41795242212719774,
            0.08272587159409578,
        ),
        v(
            -0.35341555117886503,
            -0.440549416762456,
            0.06440323916110777,
        ),
        v(-0.363402266683142, -0.5347845848543387, 0.06219273065875497),
        v(
            -0.37323333726846397,
            -0.3278605468416258,
            0.19674545372062163,
        ),
        v(
            -0.41746852457873135,
            -0.3726010228001577,
            0.07821824169409448,
        ),
        v(
            -0.4961249312275375,
            -0.46775360592045573,
            0.11612750074762926,
        ),
        v(
            -0.45329868595086736,
            -0.4903013788855213,
            0.09931602784355886,
        ),
        v(
            -0.33665278274349025,
            -0.5192321317379919,
            0.16632024464551198,
        ),
        v(
            -0.3367526544630215,
            -0.39354006933511765,
            0.15618059390076092,
        ),
        v(
            -0.27179530389084017,
            -0.4747705007735852,
            0.17341225961906592,
        ),
        v(
            -0.2915026484330552,
            -0.5109443012942426,
            0.08102477146472215,
        ),
    ])
    .unwrap();
    let id = Isometry3::identity();
    let (_, signed) = Oracle::new(&a, &b).query(&id, &id);
    assert!(signed < -3e-4, "parry: {signed:e}");
    let prox = closest_features(&a, &id, &b, &id, None);
    assert!(prox.penetrating, "{prox:?}");
    let points: Vec<ContactPoint> = contact_points(&a, &id, &b, &id, &prox, 1e-5);
    let depth = points
        .iter()
        .map(|c| -c.separation)
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(
        (depth - 3.392487e-4).abs() < 1e-9,
        "deepest contact point {depth:e} m, the overlap is 3.392487e-4 m: {points:?}"
    );
}
