//! Hostile input (issue 8), as property tests: arbitrary bytes, arbitrary
//! and mutated TOML into the scene loader; arbitrary and mutated OBJ, STL
//! and DXF files into the mesh loaders; random degenerate matrices into the
//! Dantzig LCP solver.
//!
//! The contract: never a panic (nor an abort from a huge allocation); a
//! loader error is one line that starts with the scene file's name; a scene
//! asking for absurd work (10⁹ bodies, a file over the size limits) is
//! refused at once; an LCP answer is either verified against the
//! complementarity conditions (scaled violation ≤ 1e-9, the solver's own
//! documented measure, recomputed here independently) or an error, never
//! NaN. Seeds are fixed so CI is repeatable; `FUZZ_CASES=N` runs more.

mod common;

use nalgebra::DMatrix;
use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use rigidsim::contact::lcp::{self, LcpProblem};
use rigidsim::scene::{self, MAX_BODIES, MAX_SCENE_BYTES};
use std::path::Path;
use std::time::{Duration, Instant};

fn cases(default: u32) -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

fn config(default_cases: u32, seed: u64) -> ProptestConfig {
    ProptestConfig {
        cases: cases(default_cases),
        rng_seed: RngSeed::Fixed(seed),
        max_shrink_iters: 200,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

/// Loading finished within `limit` and either succeeded or failed with one
/// line that names the file first.
fn check_loaded(
    result: Result<scene::Scene, scene::SceneError>,
    file: &Path,
    started: Instant,
    limit: Duration,
) -> Result<(), TestCaseError> {
    loaded_ok(result, file, started, limit).map_err(TestCaseError::fail)
}

fn loaded_ok(
    result: Result<scene::Scene, scene::SceneError>,
    file: &Path,
    started: Instant,
    limit: Duration,
) -> Result<(), String> {
    let took = started.elapsed();
    if took > limit {
        return Err(format!("took {took:?} (limit {limit:?})"));
    }
    if let Err(e) = result {
        let msg = e.to_string();
        let prefix = format!("{}: ", file.display());
        if msg.contains('\n') {
            return Err(format!("error is not one line: {msg}"));
        }
        if !msg.starts_with(&prefix) || msg.len() <= prefix.len() {
            return Err(format!("error does not name the file: {msg}"));
        }
        if msg.len() > 2000 {
            return Err(format!("message of {} bytes", msg.len()));
        }
    }
    Ok(())
}

// ------------------------------------------------------------------ scene TOML

/// The bundled scenes, the seeds of the mutations.
fn bundled() -> Vec<String> {
    let mut out: Vec<String> = std::fs::read_dir("scenes")
        .unwrap()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "toml"))
        .map(|e| std::fs::read_to_string(e.path()).unwrap())
        .collect();
    out.sort();
    out
}

/// Values a hostile or careless file might hold in place of a number.
const HOSTILE: &[&str] = &[
    "0",
    "-0.0",
    "-1",
    "1e308",
    "-1e308",
    "1e-320",
    "nan",
    "inf",
    "-inf",
    "18446744073709551615",
    "99999999999999999999999",
    "4294967295",
    "1000000000",
    "\"text\"",
    "[]",
    "[1.0]",
    "{}",
    "true",
    "[[1.0, 2.0], [3.0]]",
    "{ box = { half_extents = [1e-300, 1e-300, 1e-300] } }",
    "{ sphere = { radius = 1.0, subdivisions = 4294967295 } }",
    "{ cylinder = { radius = 1.0, half_height = 1.0, sides = 4294967295 } }",
    "{ mesh = { path = \"/dev/zero\" } }",
    "{ mesh = { path = \"../../../../etc/passwd.obj\" } }",
];

#[derive(Clone, Debug)]
enum Mutation {
    /// Replace the n-th number (cyclically) with a hostile value.
    Number(usize, usize),
    /// Delete a byte range (start, length), both taken modulo the text size.
    Delete(usize, usize),
    /// Duplicate a line.
    DuplicateLine(usize),
    /// Insert a line: a hostile key or table.
    Insert(usize, usize),
    /// Overwrite one byte.
    Byte(usize, u8),
}

const INSERTS: &[&str] = &[
    "[world]",
    "[[bodies]]",
    "[[scatter]]\nobjects = [\"cube\"]\ncount = 1000000000\nmin = [0,0,0]\nmax = [1,1,1]",
    "[[scatter]]\nobjects = [\"floor\"]\ncount = 18446744073709551615\nmin = [0,0,0]\nmax = [1,1,1]",
    "[[forces]]\nbody = 4294967296\nforce = [1, 0, 0]",
    "[objects.\"\u{0}\"]",
    "unknown_key = 1",
    "dt = -1",
    "a = \"\\uD800\"",
    "[render]\nsize = [100000, 100000]",
    "x = [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[]]]]]]]]]]]]]]]]]]]]]]]]]]]]]",
];

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 0..HOSTILE.len()).prop_map(|(n, v)| Mutation::Number(n, v)),
        (any::<usize>(), 1usize..64).prop_map(|(s, l)| Mutation::Delete(s, l)),
        any::<usize>().prop_map(Mutation::DuplicateLine),
        (any::<usize>(), 0..INSERTS.len()).prop_map(|(at, k)| Mutation::Insert(at, k)),
        (any::<usize>(), any::<u8>()).prop_map(|(at, b)| Mutation::Byte(at, b)),
    ]
}

fn apply(text: &str, m: &Mutation) -> String {
    let bytes = text.as_bytes();
    let out: Vec<u8> = match *m {
        Mutation::Number(n, v) => {
            // Spans of number-like characters.
            let mut spans = Vec::new();
            let mut start = None;
            for (i, &c) in bytes.iter().enumerate() {
                let num = c.is_ascii_digit() || c == b'.' || c == b'-' || c == b'e';
                match (num, start) {
                    (true, None) if c.is_ascii_digit() || c == b'-' => start = Some(i),
                    (false, Some(s)) => {
                        spans.push((s, i));
                        start = None;
                    }
                    _ => {}
                }
            }
            if spans.is_empty() {
                return text.to_string();
            }
            let (s, e) = spans[n % spans.len()];
            [&bytes[..s], HOSTILE[v].as_bytes(), &bytes[e..]].concat()
        }
        Mutation::Delete(s, l) => {
            if bytes.is_empty() {
                return String::new();
            }
            let s = s % bytes.len();
            let e = (s + l).min(bytes.len());
            [&bytes[..s], &bytes[e..]].concat()
        }
        Mutation::DuplicateLine(n) => {
            let lines: Vec<&str> = text.lines().collect();
            if lines.is_empty() {
                return text.to_string();
            }
            let k = n % lines.len();
            let mut v = lines.clone();
            v.insert(k, lines[k]);
            return v.join("\n");
        }
        Mutation::Insert(at, k) => {
            let lines: Vec<&str> = text.lines().collect();
            let k2 = at % (lines.len() + 1);
            let mut v = lines.clone();
            v.insert(k2, INSERTS[k]);
            return v.join("\n");
        }
        Mutation::Byte(at, b) => {
            if bytes.is_empty() {
                return String::new();
            }
            let mut v = bytes.to_vec();
            v[at % bytes.len()] = b;
            v
        }
    };
    String::from_utf8_lossy(&out).into_owned()
}

proptest! {
    #![proptest_config(config(400, 1))]

    /// Arbitrary bytes as a scene (through `from_str`, and as a file through `load`).
    #[test]
    fn arbitrary_bytes_as_a_scene_are_an_error_not_a_panic(bytes in prop::collection::vec(any::<u8>(), 0..3000)) {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("fuzz.toml");
        let started = Instant::now();
        let text = String::from_utf8_lossy(&bytes);
        let r = scene::from_str(&text, &file, dir.path());
        check_loaded(r, &file, started, Duration::from_secs(5))?;
        std::fs::write(&file, &bytes).unwrap();
        let started = Instant::now();
        check_loaded(scene::load(&file), &file, started, Duration::from_secs(5))?;
    }
}

proptest! {
    #![proptest_config(config(600, 2))]

    /// Bundled scenes with 1–6 mutations: hostile numbers, deleted ranges,
    /// duplicated lines, inserted tables (a 10⁹ scatter, a force on body
    /// 2³²), flipped bytes. Each loads or is refused with one line, fast.
    #[test]
    fn mutated_scenes_are_refused_with_one_line_or_load(
        which in any::<usize>(),
        mutations in prop::collection::vec(mutation(), 1..7),
    ) {
        let scenes = bundled();
        let mut text = scenes[which % scenes.len()].clone();
        for m in &mutations {
            text = apply(&text, m);
        }
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("mutated.toml");
        let started = Instant::now();
        let r = scene::from_str(&text, &file, dir.path());
        check_loaded(r, &file, started, Duration::from_secs(10))?;
    }
}

/// Shapes with hostile parameters, each in an otherwise valid scene.
fn hostile_shape() -> impl Strategy<Value = String> {
    let num = prop_oneof![
        Just("0".to_string()),
        Just("-1.0".to_string()),
        Just("1e-300".to_string()),
        Just("1e300".to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        (1e-4..10.0f64).prop_map(|x| x.to_string()),
    ];
    let count = prop_oneof![
        Just("0".to_string()),
        Just("3".to_string()),
        Just("513".to_string()),
        Just("4294967295".to_string()),
        (0u32..600).prop_map(|x| x.to_string()),
    ];
    prop_oneof![
        (num.clone(), num.clone(), num.clone())
            .prop_map(|(a, b, c)| format!("{{ box = {{ half_extents = [{a}, {b}, {c}] }} }}")),
        (num.clone(), count.clone())
            .prop_map(|(r, n)| format!("{{ sphere = {{ radius = {r}, subdivisions = {n} }} }}")),
        (num.clone(), num.clone(), count.clone()).prop_map(|(r, h, n)| format!(
            "{{ cylinder = {{ radius = {r}, half_height = {h}, sides = {n} }} }}"
        )),
        (num.clone(), num.clone(), num.clone(), count.clone()).prop_map(|(a, t, h, n)| format!(
            "{{ nut = {{ across_flats = {a}, thickness = {t}, hole_radius = {h}, sides = {n} }} }}"
        )),
        (num.clone(), num.clone(), count.clone()).prop_map(|(a, b, n)| format!(
            "{{ bolt = {{ head_across_flats = {a}, shaft_length = {b}, sides = {n} }} }}"
        )),
        (num.clone(), num).prop_map(|(a, b)| format!(
            "{{ compound = [{{ shape = {{ box = {{ half_extents = [{a}, 1.0, 1.0] }} }} }}, \
             {{ shape = {{ box = {{ half_extents = [1.0, {b}, 1.0] }} }}, position = [{a}, 0.0, 0.0] }}] }}"
        )),
    ]
}

proptest! {
    #![proptest_config(config(300, 3))]

    /// Procedural shapes with zero, negative, tiny, huge, NaN, infinite
    /// sizes and side counts up to 2³² − 1: built quickly or refused.
    #[test]
    fn hostile_shape_parameters_are_refused_with_one_line_or_load(
        shape in hostile_shape(),
        mass in prop_oneof![Just("1.0"), Just("0.0"), Just("-1.0"), Just("1e-300"), Just("1e300")],
        count in prop_oneof![Just(0u64), Just(3u64), Just(1_000_000_000u64), Just(u64::MAX)],
    ) {
        let text = format!(
            "[world]\nduration = 1.0\n[objects.thing]\nshape = {shape}\nmass = {mass}\n\
             [[bodies]]\nobject = \"thing\"\n\
             [[scatter]]\nobjects = [\"thing\"]\ncount = {count}\nmin = [-100.0, -100.0, 10.0]\n\
             max = [100.0, 100.0, 200.0]\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("shape.toml");
        let started = Instant::now();
        let r = scene::from_str(&text, &file, dir.path());
        check_loaded(r, &file, started, Duration::from_secs(10))?;
    }
}

/// 10⁹ bodies, u64::MAX bodies, or two scatters whose counts overflow: all
/// refused before any body is placed (well under 100 ms), naming the limit.
#[test]
fn a_billion_body_scatter_is_refused_at_once() {
    let base = "[world]\nduration = 1.0\n[objects.cube]\nshape = { box = { half_extents = [0.1, 0.1, 0.1] } }\n\
                mass = 1.0\n";
    let scatter = |n: u64| {
        format!(
            "[[scatter]]\nobjects = [\"cube\"]\ncount = {n}\nmin = [0.0, 0.0, 0.0]\nmax = [1e6, 1e6, 1e6]\n"
        )
    };
    for extra in [
        scatter(1_000_000_000),
        scatter(u64::MAX),
        scatter(MAX_BODIES + 1),
        format!("{}{}", scatter(u64::MAX / 2 + 1), scatter(u64::MAX / 2 + 1)),
    ] {
        let text = format!("{base}{extra}");
        let started = Instant::now();
        let e = scene::from_str(&text, Path::new("huge.toml"), Path::new("."))
            .expect_err("must be refused");
        let took = started.elapsed();
        let msg = e.to_string();
        assert!(took < Duration::from_millis(100), "took {took:?}");
        assert!(msg.starts_with("huge.toml: scatter["), "{msg}");
        assert!(msg.contains(&MAX_BODIES.to_string()), "{msg}");
    }
}

/// A scene file one byte over the limit (a sparse file: nothing is written)
/// is refused from its size alone.
#[test]
fn scene_file_over_the_size_limit_is_refused_before_reading() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("big.toml");
    std::fs::File::create(&file)
        .unwrap()
        .set_len(MAX_SCENE_BYTES + 1)
        .unwrap();
    let started = Instant::now();
    let msg = scene::load(&file).expect_err("must be refused").to_string();
    assert!(started.elapsed() < Duration::from_millis(100));
    assert!(msg.starts_with(&format!("{}: ", file.display())), "{msg}");
    assert!(msg.contains(&MAX_SCENE_BYTES.to_string()), "{msg}");
}

// ------------------------------------------------------------------ mesh files

fn mesh_scene(file: &str, hull: bool) -> String {
    format!(
        "[world]\nduration = 1.0\n[objects.part]\nshape = {{ mesh = {{ path = \"{file}\", hull = {hull} }} }}\n\
         mass = 1.0\n[[bodies]]\nobject = \"part\"\n"
    )
}

/// Loads a scene whose one object is the mesh `bytes` saved as `name`: it
/// loads, or fails with one line naming the scene file and the shape field.
fn mesh_loads_or_names_it(name: &str, bytes: &[u8], hull: bool) -> Result<(), String> {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join(name), bytes).unwrap();
    let file = dir.path().join("mesh.toml");
    let started = Instant::now();
    let r = scene::from_str(&mesh_scene(name, hull), &file, dir.path());
    if let Err(e) = &r {
        if !e.to_string().contains("objects.part.shape") {
            return Err(format!("error does not name the field: {e}"));
        }
    }
    loaded_ok(r, &file, started, Duration::from_secs(10))
}

fn load_mesh(name: &str, bytes: &[u8], hull: bool) -> Result<(), TestCaseError> {
    mesh_loads_or_names_it(name, bytes, hull).map_err(TestCaseError::fail)
}

/// A 10 GB mesh file (sparse: nothing is written) is refused from its size.
#[test]
fn ten_gigabyte_mesh_is_refused_before_reading() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["huge.obj", "huge.stl", "huge.dxf"] {
        std::fs::File::create(dir.path().join(name))
            .unwrap()
            .set_len(10 << 30)
            .unwrap();
        let started = Instant::now();
        let msg = scene::from_str(&mesh_scene(name, false), Path::new("m.toml"), dir.path())
            .expect_err("must be refused")
            .to_string();
        assert!(started.elapsed() < Duration::from_millis(100), "{name}");
        assert!(msg.starts_with("m.toml: objects.part.shape"), "{msg}");
        assert!(
            msg.contains("10737418240") && msg.contains("limit"),
            "{name}: {msg}"
        );
    }
}

/// A binary STL whose header claims 2³² − 1 triangles (or 10⁸) in a file of
/// a few hundred bytes: refused, not allocated.
#[test]
fn binary_stl_claiming_billions_of_triangles_is_refused() {
    for claimed in [u32::MAX, 100_000_000, 3] {
        let mut bytes = vec![b'x'; 80];
        bytes.extend_from_slice(&claimed.to_le_bytes());
        bytes.extend(std::iter::repeat_n(0u8, 50 * 2));
        let started = Instant::now();
        let r = mesh_loads_or_names_it("claims.stl", &bytes, false);
        assert!(r.is_ok(), "{claimed} triangles: {r:?}");
        assert!(started.elapsed() < Duration::from_secs(2));
    }
}

fn data(name: &str) -> Vec<u8> {
    std::fs::read(Path::new("tests/data").join(name)).unwrap()
}

/// Byte-level mutations of a valid file: flips, truncation, duplication.
fn mutate_bytes(mut v: Vec<u8>, edits: &[(usize, u8, u8)]) -> Vec<u8> {
    for &(at, kind, b) in edits {
        if v.is_empty() {
            v.push(b);
            continue;
        }
        let at = at % v.len();
        match kind % 4 {
            0 => v[at] = b,
            1 => v.truncate(at),
            2 => {
                let end = (at + 1 + b as usize).min(v.len());
                let chunk = v[at..end].to_vec();
                v.splice(at..at, chunk);
            }
            _ => {
                let end = (at + 1 + b as usize % 16).min(v.len());
                v.drain(at..end);
            }
        }
    }
    v
}

proptest! {
    #![proptest_config(config(150, 4))]

    /// Arbitrary bytes as OBJ, STL and DXF, convex parts or hulls.
    #[test]
    fn arbitrary_bytes_as_a_mesh_are_an_error_not_a_panic(
        bytes in prop::collection::vec(any::<u8>(), 0..4000),
        ext in prop_oneof![Just("obj"), Just("stl"), Just("dxf")],
        hull in any::<bool>(),
    ) {
        load_mesh(&format!("m.{ext}"), &bytes, hull)?;
    }

    /// Arbitrary text of mesh-like lines: `v`/`f`/`o` records with hostile
    /// numbers and indices (OBJ), group code / value pairs (DXF).
    #[test]
    fn arbitrary_mesh_like_text_is_an_error_not_a_panic(
        lines in prop::collection::vec(
            (0usize..8, prop_oneof![
                Just("0".to_string()), Just("-1".to_string()), Just("1e308".to_string()),
                Just("nan".to_string()), Just("inf".to_string()), Just("99999999999".to_string()),
                (-2.0..2.0f64).prop_map(|x| x.to_string()), (0u32..20).prop_map(|x| x.to_string()),
            ]),
            0..200,
        ),
        hull in any::<bool>(),
    ) {
        let mut obj = String::new();
        let mut dxf = String::from("0\nSECTION\n2\nENTITIES\n");
        for (kind, value) in &lines {
            match kind {
                0..=2 => obj += &format!("v {value} {value} 0.5\n"),
                3 => obj += &format!("f 1 2 {value}\n"),
                4 => obj += &format!("f {value} {value} {value} {value}\n"),
                5 => obj += &format!("o part{value}\n"),
                _ => obj += &format!("vn {value} 0 1\n"),
            }
            match kind {
                0 => dxf += "0\n3DFACE\n",
                1..=6 => dxf += &format!("{}\n{value}\n", [10, 20, 30, 11, 21, 31][kind - 1]),
                _ => dxf += &format!("{value}\n"),
            }
        }
        dxf += "0\nENDSEC\n0\nEOF\n";
        load_mesh("m.obj", obj.as_bytes(), hull)?;
        load_mesh("m.dxf", dxf.as_bytes(), hull)?;
    }

    /// The valid test meshes with random byte edits.
    #[test]
    fn mutated_meshes_are_refused_with_one_line_or_load(
        which in 0usize..6,
        edits in prop::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..6),
        hull in any::<bool>(),
    ) {
        let (name, ext) = [
            ("box_ascii.stl", "stl"),
            ("box_quads.dxf", "dxf"),
            ("box_triangles.dxf", "dxf"),
            ("dented_cube.obj", "obj"),
            ("two_cubes.obj", "obj"),
            ("l_shape.obj", "obj"),
        ][which];
        let bytes = mutate_bytes(data(name), &edits);
        load_mesh(&format!("m.{ext}"), &bytes, hull)?;
    }
}

// ------------------------------------------------------------------ LCP

/// Families of matrices the contact solver can meet, and worse.
#[derive(Clone, Copy, Debug)]
enum Family {
    /// GᵀG with G k×n, k < n: rank k.
    RankDeficient,
    /// Q diag(10^(−c·i/(n−1))) Qᵀ, condition 10^c with c up to 16.
    Conditioned,
    /// GᵀG with some rows and columns zeroed.
    ZeroRows,
    /// GᵀG with a row and column duplicated (two identical contacts).
    Duplicated,
    /// All zero.
    Zero,
    /// Full rank, entries scaled by 10^±150.
    Scaled,
}

#[derive(Clone, Debug)]
struct Case {
    family: Family,
    a: Vec<f64>,
    b: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    findex: Vec<Option<usize>>,
}

fn lcp_case() -> impl Strategy<Value = Case> {
    let family = prop_oneof![
        Just(Family::RankDeficient),
        Just(Family::Conditioned),
        Just(Family::ZeroRows),
        Just(Family::Duplicated),
        Just(Family::Zero),
        Just(Family::Scaled),
    ];
    (family, 1usize..25, any::<u64>()).prop_map(|(family, n, seed)| build_case(family, n, seed))
}

/// SplitMix64 (so a case is a pure function of its seed).
fn rng(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

fn build_case(family: Family, n: usize, seed: u64) -> Case {
    let mut s = seed;
    let normal = |s: &mut u64| {
        let u = rng(s).max(1e-300);
        let v = rng(s);
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    let gram = |k: usize, s: &mut u64| {
        let g = DMatrix::from_fn(k, n, |_, _| normal(s));
        g.transpose() * g
    };
    let mut a = match family {
        Family::RankDeficient => {
            let k = 1 + (rng(&mut s) * n.saturating_sub(1) as f64) as usize;
            gram(k.max(1), &mut s)
        }
        Family::Conditioned => {
            let c = 1.0 + 15.0 * rng(&mut s);
            let q = DMatrix::from_fn(n, n, |_, _| normal(&mut s)).qr().q();
            let d = nalgebra::DVector::from_fn(n, |i, _| {
                10f64.powf(-c * i as f64 / (n.max(2) - 1) as f64)
            });
            &q * DMatrix::from_diagonal(&d) * q.transpose()
        }
        Family::ZeroRows => {
            let mut m = gram(n + 1, &mut s);
            for _ in 0..1 + n / 3 {
                let k = (rng(&mut s) * n as f64) as usize % n;
                m.row_mut(k).fill(0.0);
                m.column_mut(k).fill(0.0);
            }
            m
        }
        Family::Duplicated => {
            let mut m = gram(n + 1, &mut s);
            if n > 1 {
                let i = (rng(&mut s) * n as f64) as usize % n;
                let j = (i + 1) % n;
                let ri = m.row(i).clone_owned();
                m.set_row(j, &ri);
                let ci = m.column(i).clone_owned();
                m.set_column(j, &ci);
            }
            m
        }
        Family::Zero => DMatrix::zeros(n, n),
        Family::Scaled => {
            let scale = 10f64.powf(300.0 * rng(&mut s) - 150.0);
            gram(n + 2, &mut s) * scale
        }
    };
    a = (&a + a.transpose()) * 0.5;
    let bscale = 10f64.powf(6.0 * rng(&mut s) - 3.0);
    let b: Vec<f64> = (0..n)
        .map(|_| {
            if rng(&mut s) < 0.2 {
                0.0
            } else {
                normal(&mut s) * bscale
            }
        })
        .collect();
    let mut lo = vec![0.0; n];
    let mut hi = vec![f64::INFINITY; n];
    let mut findex = vec![None; n];
    for i in 0..n {
        let r = rng(&mut s);
        if r < 0.15 {
            lo[i] = -2.0 * rng(&mut s);
            hi[i] = 2.0 * rng(&mut s);
        } else if r < 0.25 {
            lo[i] = f64::NEG_INFINITY;
        } else if r < 0.45 && i > 0 {
            let j = (rng(&mut s) * i as f64) as usize;
            if findex[j].is_none() {
                let mu = 1.5 * rng(&mut s);
                lo[i] = -mu;
                hi[i] = mu;
                findex[i] = Some(j);
            }
        }
    }
    Case {
        family,
        a: a.transpose().as_slice().to_vec(),
        b,
        lo,
        hi,
        findex,
    }
}

proptest! {
    #![proptest_config(config(1500, 5))]

    /// Rank-deficient, ill-conditioned (to 1e16), zero-row, duplicated-row,
    /// all-zero and extremely scaled (10^±150) symmetric PSD matrices with
    /// random boxes and friction rows: a solution that verifies to 1e-9, or
    /// an error with a message; never NaN, never a panic, under a second.
    #[test]
    fn lcp_on_degenerate_matrices_is_verified_or_an_error(case in lcp_case()) {
        let p = LcpProblem::boxed(&case.a, &case.b, &case.lo, &case.hi).with_friction(&case.findex);
        let started = Instant::now();
        let result = lcp::solve(&p);
        prop_assert!(started.elapsed() < Duration::from_secs(1), "{:?}: took {:?}", case.family, started.elapsed());
        match result {
            Ok(sol) => {
                let v = common::lcp_violation(&p, &sol).map_err(|e| TestCaseError::fail(format!("{:?}: {e}", case.family)))?;
                prop_assert!(v <= 1e-9, "{:?}: violation {:e} (solver said {:e})", case.family, v, sol.max_violation);
            }
            Err(e) => {
                let msg = e.to_string();
                prop_assert!(!msg.is_empty() && !msg.contains("NaN"), "{msg}");
            }
        }
    }

    /// The standard LCP (lo = 0, hi = ∞) on the same families: for PSD A it
    /// has a solution exactly when b is not pushed along a null direction;
    /// whatever the answer, it is verified or an error, and with A = 0 it is
    /// x = 0 when b ≥ 0.
    #[test]
    fn standard_lcp_on_degenerate_matrices_is_verified_or_an_error(case in lcp_case()) {
        let p = LcpProblem::standard(&case.a, &case.b);
        match lcp::solve(&p) {
            Ok(sol) => {
                let v = common::lcp_violation(&p, &sol).map_err(TestCaseError::fail)?;
                prop_assert!(v <= 1e-9, "{:?}: violation {:e}", case.family, v);
            }
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
        if matches!(case.family, Family::Zero) && case.b.iter().all(|&x| x >= 0.0) {
            let sol = lcp::solve(&p).unwrap();
            prop_assert!(sol.x.iter().all(|&x| x == 0.0));
        }
    }
}

/// Non-finite input is an error that names where it is, not a NaN answer.
#[test]
fn lcp_with_non_finite_input_names_it() {
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let a = [2.0, bad, bad, 2.0];
        let e = lcp::solve(&LcpProblem::standard(&a, &[1.0, -1.0])).unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");
        let e = lcp::solve(&LcpProblem::standard(&[1.0], &[bad])).unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");
    }
}

/// `cargo test --release --test fuzz_input lcp_outcome_census -- --ignored
/// --nocapture`: how the solver answers each family (for docs/stability.md).
#[test]
#[ignore = "measurement"]
fn lcp_outcome_census() {
    use proptest::strategy::ValueTree;
    let mut runner = proptest::test_runner::TestRunner::new(config(0, 5));
    let mut tally: std::collections::BTreeMap<String, [usize; 3]> = Default::default();
    let mut worst: f64 = 0.0;
    for _ in 0..cases(20_000) {
        let case = lcp_case().new_tree(&mut runner).unwrap().current();
        let p = LcpProblem::boxed(&case.a, &case.b, &case.lo, &case.hi).with_friction(&case.findex);
        let t = tally.entry(format!("{:?}", case.family)).or_default();
        match lcp::solve(&p) {
            Ok(sol) => {
                t[0] += 1;
                worst = worst.max(common::lcp_violation(&p, &sol).unwrap());
            }
            Err(lcp::LcpError::Infeasible { .. }) => t[1] += 1,
            Err(_) => t[2] += 1,
        }
    }
    println!(
        "LCP census (solved, infeasible, other error) by family: {tally:?}; worst violation {worst:.1e}"
    );
}
