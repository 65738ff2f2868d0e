//! Pixel-level checks of the off-screen renderer, run on lavapipe in CI.
//!
//! Where a test needs to know where something lands on screen, it projects
//! with nalgebra's own `look_at_rh` and `Perspective3`, not the renderer's
//! maths, so a wrong matrix in the renderer shows up as a wrong pixel.
//! A missing adapter fails every test: CI installs mesa-vulkan-drivers, so
//! no adapter there is a broken setup, not a reason to skip.

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use nalgebra::{Matrix4, Perspective3, Point3, Vector3, Vector4};
use rigidsim::render::{
    BACKGROUND, Camera, FIXED_CHECKER_DARKEN, Image, Instance, Mesh, RenderError, Renderer,
    VideoWriter, look_at_scene, write_png,
};

const IDENTITY: [f32; 4] = [1.0, 0.0, 0.0, 0.0];
const RED: [f32; 3] = [0.9, 0.1, 0.1];
const BLUE: [f32; 3] = [0.1, 0.2, 0.9];
const GREY: [f32; 3] = [0.6, 0.6, 0.6];

fn open(width: u32, height: u32, meshes: Vec<Mesh>) -> Renderer {
    match Renderer::new(width, height, meshes) {
        Ok(r) => r,
        Err(e) => panic!("cannot open a renderer: {e}"),
    }
}

fn body(mesh: usize, translation: [f32; 3], color: [f32; 3]) -> Instance {
    Instance {
        mesh,
        rotation: IDENTITY,
        translation,
        color,
        fixed: false,
    }
}

/// Pixel coordinates (x right, y down, continuous) of a world point.
fn project(camera: &Camera, width: u32, height: u32, p: [f32; 3]) -> (f32, f32) {
    let view = Matrix4::look_at_rh(
        &Point3::from(camera.eye),
        &Point3::from(camera.target),
        &Vector3::from(camera.up),
    );
    let aspect = width as f32 / height as f32;
    // Near and far do not move x and y, so any pair will do.
    let proj = Perspective3::new(aspect, camera.fov_y_deg.to_radians(), 0.1, 100.0);
    let clip = proj.as_matrix() * view * Vector4::new(p[0], p[1], p[2], 1.0);
    let (x, y) = (clip.x / clip.w, clip.y / clip.w);
    (
        (x + 1.0) * 0.5 * width as f32,
        (1.0 - y) * 0.5 * height as f32,
    )
}

fn pixel_at(image: &Image, (x, y): (f32, f32)) -> [u8; 4] {
    image.pixel(x.floor() as u32, y.floor() as u32)
}

/// Screen-space box (min x, min y, max x, max y) around the eight corners of
/// an axis-aligned box.
fn projected_box(
    camera: &Camera,
    width: u32,
    height: u32,
    centre: [f32; 3],
    half: [f32; 3],
) -> [f32; 4] {
    let mut b = [f32::MAX, f32::MAX, f32::MIN, f32::MIN];
    for i in 0..8 {
        let corner: [f32; 3] =
            std::array::from_fn(|k| centre[k] + if i >> k & 1 == 0 { -half[k] } else { half[k] });
        let (x, y) = project(camera, width, height, corner);
        b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
    }
    b
}

fn inside(b: &[f32; 4], margin: f32, x: f32, y: f32) -> bool {
    x >= b[0] - margin && x <= b[2] + margin && y >= b[1] - margin && y <= b[3] + margin
}

fn is_red(p: [u8; 4]) -> bool {
    let [r, g, b, _] = p.map(u32::from);
    r > 60 && r > 2 * g && r > 2 * b
}

fn is_blue(p: [u8; 4]) -> bool {
    let [r, g, b, _] = p.map(u32::from);
    b > 60 && b > 2 * r && b > 2 * g
}

fn is_grey(p: [u8; 4]) -> bool {
    let [r, g, b, _] = p.map(i32::from);
    r.max(g).max(b) - r.min(g).min(b) <= 4
}

/// A 4 x 4 x 0.2 floor with its top at z = 0, and a unit cube floating with
/// its centre at z = 1.
const FLOOR_HALF: [f32; 3] = [2.0, 2.0, 0.1];
const FLOOR_AT: [f32; 3] = [0.0, 0.0, -0.1];
const CUBE_HALF: [f32; 3] = [0.5, 0.5, 0.5];
const CUBE_AT: [f32; 3] = [0.0, 0.0, 1.0];

fn cube_over_floor(floor_fixed: bool) -> (Vec<Mesh>, Vec<Instance>, Camera) {
    let meshes = vec![Mesh::cuboid(FLOOR_HALF), Mesh::cuboid(CUBE_HALF)];
    let instances = vec![
        Instance {
            fixed: floor_fixed,
            ..body(0, FLOOR_AT, GREY)
        },
        body(1, CUBE_AT, RED),
    ];
    let camera = Camera::looking_at([4.0, -6.0, 3.5], [0.0, 0.0, 0.5]);
    (meshes, instances, camera)
}

/// Points on the floor's top face, spread over it, away from its edges.
fn floor_top_samples() -> Vec<[f32; 3]> {
    let mut points = Vec::new();
    for x in [-1.55, -0.85, -0.15, 0.55, 1.25] {
        for y in [-1.45, -0.75, 0.35, 1.05, 1.65] {
            points.push([x, y, 0.0]);
        }
    }
    points
}

#[test]
fn red_cube_over_grey_floor_lands_where_projected() {
    let (w, h) = (320, 240);
    let (meshes, instances, camera) = cube_over_floor(true);
    let image = open(w, h, meshes).render(&camera, &instances).unwrap();

    let centre = pixel_at(&image, project(&camera, w, h, CUBE_AT));
    assert!(is_red(centre), "cube centre pixel {centre:?} is not red");

    let floor_box = projected_box(&camera, w, h, FLOOR_AT, FLOOR_HALF);
    let cube_box = projected_box(&camera, w, h, CUBE_AT, CUBE_HALF);
    let mut background_checked = 0;
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (x as f32 + 0.5, y as f32 + 0.5);
            // 2 px: antialiased edges may bleed into the neighbour pixel.
            if inside(&floor_box, 2.0, fx, fy) || inside(&cube_box, 2.0, fx, fy) {
                continue;
            }
            assert_eq!(image.pixel(x, y), BACKGROUND, "pixel ({x}, {y})");
            background_checked += 1;
        }
    }
    assert!(
        background_checked > 5000,
        "only {background_checked} background pixels checked: the scene fills the frame"
    );

    let mut floor_checked = 0;
    for p in floor_top_samples() {
        let (x, y) = project(&camera, w, h, p);
        if inside(&cube_box, 2.0, x, y) {
            continue;
        }
        let px = pixel_at(&image, (x, y));
        assert!(is_grey(px), "floor pixel {px:?} at {p:?} is not grey");
        assert!(
            (60..=170).contains(&px[0]),
            "floor pixel {px:?} at {p:?} has the wrong brightness"
        );
        floor_checked += 1;
    }
    assert!(
        floor_checked >= 15,
        "only {floor_checked} floor samples visible"
    );
}

#[test]
fn fixed_bodies_show_a_checker() {
    let (w, h) = (320, 240);
    let tones = |fixed: bool| {
        let (meshes, instances, camera) = cube_over_floor(fixed);
        let image = open(w, h, meshes).render(&camera, &instances).unwrap();
        let cube_box = projected_box(&camera, w, h, CUBE_AT, CUBE_HALF);
        let mut tones: Vec<[u8; 4]> = floor_top_samples()
            .into_iter()
            .map(|p| project(&camera, w, h, p))
            .filter(|&(x, y)| !inside(&cube_box, 2.0, x, y))
            .map(|xy| pixel_at(&image, xy))
            .collect();
        tones.sort();
        tones.dedup();
        tones
    };
    // Flat shading: one face, one normal, one colour when free.
    let free = tones(false);
    assert_eq!(
        free.len(),
        1,
        "free floor top shows several tones: {free:?}"
    );
    let fixed = tones(true);
    assert_eq!(
        fixed.len(),
        2,
        "fixed floor top should show two tones: {fixed:?}"
    );
    let ratio = f32::from(fixed[0][0]) / f32::from(fixed[1][0]);
    assert!(
        (ratio - FIXED_CHECKER_DARKEN).abs() < 0.02,
        "checker tones {fixed:?} differ by {ratio}"
    );
}

#[test]
fn nearer_cube_hides_the_farther_one_whatever_the_draw_order() {
    let (w, h) = (200, 150);
    let camera = Camera::looking_at([-6.0, 0.0, 0.0], [0.0, 0.0, 0.0]);
    let mut renderer = open(w, h, vec![Mesh::cuboid(CUBE_HALF)]);
    let near = [0.0, 0.0, 0.0];
    let far = [2.0, 0.0, 0.0];
    let overlap = project(&camera, w, h, near);

    for (blue_at, red_at, expect_blue) in [(near, far, true), (far, near, false)] {
        let blue = body(0, blue_at, BLUE);
        let red = body(0, red_at, RED);
        for order in [[red, blue], [blue, red]] {
            let image = renderer.render(&camera, &order).unwrap();
            let px = pixel_at(&image, overlap);
            if expect_blue {
                assert!(is_blue(px), "blue in front, got {px:?}");
            } else {
                assert!(is_red(px), "red in front, got {px:?}");
            }
        }
    }
}

/// Two unit cubes side by side in one mesh, like a body made of convex parts.
fn two_part_mesh() -> Mesh {
    let cube = Mesh::cuboid(CUBE_HALF);
    let mut mesh = Mesh::default();
    for dx in [-0.8, 0.8] {
        let base = mesh.positions.len() as u32;
        mesh.positions
            .extend(cube.positions.iter().map(|p| [p[0] + dx, p[1], p[2]]));
        mesh.indices.extend(cube.indices.iter().map(|i| i + base));
    }
    mesh
}

#[test]
fn winding_and_vertex_sharing_do_not_change_the_picture() {
    let (w, h) = (160, 120);
    let camera = Camera::looking_at([2.5, -4.0, 3.0], [0.0, 0.0, 0.0]);
    let render = |mesh: Mesh| {
        let instance = Instance {
            rotation: [0.9, 0.1, 0.2, 0.3],
            ..body(0, [0.0; 3], RED)
        };
        open(w, h, vec![mesh]).render(&camera, &[instance]).unwrap()
    };
    let reference = render(two_part_mesh());

    let mut inside_out = two_part_mesh();
    inside_out.indices.reverse();
    assert_eq!(render(inside_out), reference, "every triangle reversed");

    let mut one_part_inside_out = two_part_mesh();
    let half = one_part_inside_out.indices.len() / 2;
    one_part_inside_out.indices[half..].reverse();
    assert_eq!(
        render(one_part_inside_out),
        reference,
        "second part reversed"
    );

    // STL style: three vertices of its own for every triangle.
    let shared = two_part_mesh();
    let unshared = Mesh {
        positions: shared
            .indices
            .iter()
            .map(|&i| shared.positions[i as usize])
            .collect(),
        indices: (0..shared.indices.len() as u32).collect(),
    };
    assert_eq!(render(unshared), reference, "vertices not shared");

    // Open: without its bottom faces (never seen from above) the mesh is
    // drawn two-sided; only silhouette pixels may differ.
    let mut open_mesh = two_part_mesh();
    open_mesh.indices.drain(36..42);
    open_mesh.indices.drain(0..6);
    let image = render(open_mesh);
    let differing = image
        .rgba
        .chunks(4)
        .zip(reference.rgba.chunks(4))
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        differing < (w * h / 200) as usize,
        "{differing} pixels differ for the open mesh"
    );
}

fn temp_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("rigidsim-render-{}-{name}", std::process::id()))
}

#[test]
fn odd_sized_image_survives_a_png_round_trip() {
    // 321 * 4 bytes a row is not a multiple of 256: exercises the de-padding.
    let (w, h) = (321, 179);
    let (meshes, instances, camera) = cube_over_floor(true);
    let image = open(w, h, meshes).render(&camera, &instances).unwrap();
    assert_eq!((image.width, image.height), (w, h));
    assert_eq!(image.rgba.len(), (w * h * 4) as usize);
    for (x, y) in [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
        assert_eq!(image.pixel(x, y), BACKGROUND, "corner ({x}, {y})");
    }

    let path = temp_path("round-trip.png");
    write_png(&path, &image).unwrap();
    let file = std::io::BufReader::new(std::fs::File::open(&path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut decoded = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut decoded).unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!((info.width, info.height), (w, h));
    assert_eq!(info.color_type, png::ColorType::Rgba);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    assert!(
        decoded[..info.buffer_size()] == image.rgba[..],
        "decoded bytes differ"
    );
}

fn ffmpeg_installed() -> bool {
    Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn ten_frames_make_an_mp4_when_ffmpeg_exists() {
    // Odd on both sides: the writer must pad for yuv420p.
    let (w, h) = (161, 121);
    let path = temp_path("ten-frames.mp4");
    let writer = VideoWriter::start(&path, w, h, 10).unwrap();
    if !ffmpeg_installed() {
        assert!(writer.is_none(), "start must return None without ffmpeg");
        return;
    }
    let mut writer = writer.expect("ffmpeg is installed, so start must return a writer");
    let (meshes, mut instances, camera) = cube_over_floor(true);
    let mut renderer = open(w, h, meshes);
    for frame in 0..10 {
        instances[1].translation[2] = 1.0 + 0.05 * frame as f32;
        writer
            .push(&renderer.render(&camera, &instances).unwrap())
            .unwrap();
    }
    writer.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    assert!(bytes.len() > 1000, "mp4 is only {} bytes", bytes.len());
    assert_eq!(&bytes[4..8], b"ftyp", "not an MP4 container");
}

#[test]
fn video_rejects_a_frame_of_the_wrong_size() {
    let path = temp_path("wrong-size.mp4");
    let Some(mut writer) = VideoWriter::start(&path, 64, 48, 10).unwrap() else {
        return;
    };
    let frame = Image {
        width: 32,
        height: 48,
        rgba: vec![0; 32 * 48 * 4],
    };
    assert!(matches!(
        writer.push(&frame),
        Err(RenderError::FrameSize { .. })
    ));
    drop(writer);
    let _ = std::fs::remove_file(&path);
}

/// The render rank may run the renderer and the encoder on worker threads.
#[test]
fn renderer_and_video_writer_can_move_between_threads() {
    fn send<T: Send>() {}
    send::<Renderer>();
    send::<VideoWriter>();
}

#[test]
fn instance_of_an_unknown_mesh_is_an_error() {
    let mut renderer = open(16, 16, vec![Mesh::cuboid(CUBE_HALF)]);
    let result = renderer.render(&Camera::default(), &[body(3, [0.0; 3], RED)]);
    assert!(matches!(
        result,
        Err(RenderError::UnknownMesh {
            instance: 0,
            mesh: 3,
            mesh_count: 1
        })
    ));
}

#[test]
fn look_at_scene_keeps_every_point_in_frame() {
    let (w, h) = (1280, 720);
    let points = [
        [-1.0, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
        [0.0, 0.0, 2.0],
        [0.3, -0.2, 1.2],
    ];
    let camera = look_at_scene(&points);
    for p in points {
        let (x, y) = project(&camera, w, h, p);
        assert!(
            (0.0..w as f32).contains(&x) && (0.0..h as f32).contains(&y),
            "{p:?} lands at ({x}, {y}), outside {w}x{h}"
        );
    }
    assert!(
        camera.eye[2] > camera.target[2],
        "a 3/4 view looks down on the scene"
    );
}

#[test]
fn look_at_instances_frames_whole_bodies_not_just_their_centres() {
    let (w, h) = (320, 180);
    let (meshes, instances, _) = cube_over_floor(true);
    let mut renderer = open(w, h, meshes);
    let camera = renderer.look_at_instances(&instances);
    let image = renderer.render(&camera, &instances).unwrap();
    for x in [-2.0, 2.0] {
        for y in [-2.0, 2.0] {
            let (px, py) = project(&camera, w, h, [x, y, 0.0]);
            assert!(
                (0.0..w as f32).contains(&px) && (0.0..h as f32).contains(&py),
                "floor corner ({x}, {y}) lands at ({px}, {py}), outside {w}x{h}"
            );
        }
    }
    let border = (0..w)
        .flat_map(|x| [(x, 0), (x, h - 1)])
        .chain((0..h).flat_map(|y| [(0, y), (w - 1, y)]));
    for (x, y) in border {
        assert_eq!(
            image.pixel(x, y),
            BACKGROUND,
            "body touches the frame at ({x}, {y})"
        );
    }
}

/// A UV sphere with `2 * slices * (stacks - 1)` triangles.
fn sphere(radius: f32, stacks: u32, slices: u32) -> Mesh {
    use std::f32::consts::PI;
    let mut positions = vec![[0.0, 0.0, radius], [0.0, 0.0, -radius]];
    for i in 1..stacks {
        let theta = PI * i as f32 / stacks as f32;
        for j in 0..slices {
            let phi = 2.0 * PI * j as f32 / slices as f32;
            positions.push([
                radius * theta.sin() * phi.cos(),
                radius * theta.sin() * phi.sin(),
                radius * theta.cos(),
            ]);
        }
    }
    let ring = |i: u32, j: u32| 2 + (i - 1) * slices + j % slices;
    let mut indices = Vec::new();
    for j in 0..slices {
        indices.extend([0, ring(1, j), ring(1, j + 1)]);
        indices.extend([1, ring(stacks - 1, j + 1), ring(stacks - 1, j)]);
    }
    for i in 1..stacks - 1 {
        for j in 0..slices {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            indices.extend([a, c, d, a, d, b]);
        }
    }
    Mesh { positions, indices }
}

fn ms_per_frame(renderer: &mut Renderer, camera: &Camera, instances: &[Instance]) -> f64 {
    for _ in 0..3 {
        renderer.render(camera, instances).unwrap();
    }
    let frames = 20;
    let start = Instant::now();
    for _ in 0..frames {
        renderer.render(camera, instances).unwrap();
    }
    start.elapsed().as_secs_f64() * 1e3 / f64::from(frames)
}

/// `count` bodies on a cubic grid `spacing` apart above the floor, cycling
/// through `meshes` kinds (mesh 0 is the floor), each turned a little.
fn scattered(count: usize, meshes: usize, spacing: f32) -> Vec<Instance> {
    let side = (count as f32).cbrt().ceil() as usize;
    (0..count)
        .map(|i| {
            let (x, y, z) = (i % side, (i / side) % side, i / (side * side));
            let half = (side as f32 - 1.0) * spacing * 0.5;
            let angle = i as f32 * 0.37;
            Instance {
                mesh: 1 + i % meshes,
                rotation: [(angle / 2.0).cos(), 0.0, (angle / 2.0).sin(), 0.0],
                translation: [
                    x as f32 * spacing - half,
                    y as f32 * spacing - half,
                    0.2 + z as f32 * spacing,
                ],
                color: [0.2 + 0.3 * (i % 3) as f32, 0.5, 0.8 - 0.2 * (i % 4) as f32],
                fixed: false,
            }
        })
        .collect()
}

/// Saves the benchmarked frame when `RENDER_REPORT_PNG_DIR` names a folder,
/// to see what was timed.
fn snapshot(renderer: &mut Renderer, camera: &Camera, bodies: &[Instance], name: &str) {
    if let Some(dir) = std::env::var_os("RENDER_REPORT_PNG_DIR") {
        let image = renderer.render(camera, bodies).unwrap();
        write_png(PathBuf::from(dir).join(format!("{name}.png")), &image).unwrap();
    }
}

/// Not a check: prints what a frame costs on this machine's adapter
/// (`cargo test --release --test render_pixels -- --ignored --nocapture`).
#[test]
#[ignore]
fn frame_time_report_1280x720() {
    let (w, h) = (1280, 720);
    let floor = Mesh::cuboid([1.0, 1.0, 0.05]);
    let floor_instance = Instance {
        fixed: true,
        ..body(0, [0.0, 0.0, -0.05], GREY)
    };

    // 50 object definitions of 400 triangles, one body each (SPEC 4's
    // 50-body scene, 10 cm bodies over a 2 m floor).
    let mut meshes = vec![floor.clone()];
    meshes.extend((0..50).map(|i| sphere(0.1 + 0.001 * i as f32, 11, 20)));
    assert_eq!(meshes[1].indices.len() / 3, 400);
    let started = Instant::now();
    let mut renderer = open(w, h, meshes);
    let startup = started.elapsed().as_secs_f64() * 1e3;
    let mut bodies = vec![floor_instance];
    bodies.extend(scattered(50, 50, 0.35));
    let camera = renderer.look_at_instances(&bodies);
    let fifty = ms_per_frame(&mut renderer, &camera, &bodies);
    snapshot(&mut renderer, &camera, &bodies, "fifty");
    // The same bodies close up, filling the frame: the fill-rate bound.
    let close = Camera::looking_at([0.7, -1.0, 1.1], [0.0, 0.0, 0.45]);
    let filled = ms_per_frame(&mut renderer, &close, &bodies);
    snapshot(&mut renderer, &close, &bodies, "filled");
    // Clear, copy and read back only: the floor under every frame's cost.
    let empty = ms_per_frame(&mut renderer, &close, &[]);

    // 1000 bodies of two kinds (400 and 180 triangles), 8 cm apart.
    let meshes = vec![floor, sphere(0.03, 11, 20), sphere(0.03, 10, 10)];
    let mut renderer = open(w, h, meshes);
    let mut bodies = vec![floor_instance];
    bodies.extend(scattered(1000, 2, 0.08));
    let camera = renderer.look_at_instances(&bodies);
    let thousand = ms_per_frame(&mut renderer, &camera, &bodies);
    snapshot(&mut renderer, &camera, &bodies, "thousand");

    println!(
        "adapter: {} ({}x MSAA)",
        renderer.adapter_info(),
        renderer.sample_count()
    );
    println!("startup (adapter, device, pipelines, 51 meshes): {startup:.0} ms");
    println!("50 bodies x 400 triangles, 50 meshes: {fifty:.1} ms/frame");
    println!("1000 bodies x 400/180 triangles, 2 meshes: {thousand:.1} ms/frame");
    println!("50 bodies filling the frame: {filled:.1} ms/frame");
    println!("no bodies (clear + read back): {empty:.1} ms/frame");
}
