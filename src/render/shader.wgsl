// Flat Lambert shading of instanced rigid bodies; see gpu.rs for the layout.

struct Globals {
    view_proj: mat4x4<f32>,
    // xyz: camera position.
    eye: vec4<f32>,
    // xyz: unit direction towards the key light; w: ambient fraction.
    light: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;

// Set from FIXED_CHECKER_DARKEN in mod.rs.
override checker_darken: f32;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    // Unit quaternion as (x, y, z, w).
    @location(2) rotation: vec4<f32>,
    // xyz: translation; w: checker cell size, 0 for a free body.
    @location(3) translation_cell: vec4<f32>,
    @location(4) color: vec4<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world_pos: vec3<f32>,
    @location(1) body_pos: vec3<f32>,
    @location(2) @interpolate(flat) world_normal: vec3<f32>,
    @location(3) @interpolate(flat) body_normal: vec3<f32>,
    @location(4) @interpolate(flat) color: vec3<f32>,
    @location(5) @interpolate(flat) cell: f32,
};

// q v q* for a unit quaternion, expanded: v + 2 u x (u x v + w v), u = q.xyz.
fn rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    return v + 2.0 * cross(q.xyz, cross(q.xyz, v) + q.w * v);
}

@vertex
fn vs_main(in: VertexIn) -> VertexOut {
    var out: VertexOut;
    let world = rotate(in.rotation, in.position) + in.translation_cell.xyz;
    out.clip = globals.view_proj * vec4<f32>(world, 1.0);
    out.world_pos = world;
    out.body_pos = in.position;
    out.world_normal = rotate(in.rotation, in.normal);
    out.body_normal = in.normal;
    out.color = in.color.rgb;
    out.cell = in.translation_cell.w;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    // Open meshes are drawn unculled and may be wound either way: light
    // whichever side faces the camera.
    var n = in.world_normal;
    if dot(n, globals.eye.xyz - in.world_pos) < 0.0 {
        n = -n;
    }
    var base = in.color;
    if in.cell > 0.0 {
        // Checker on the two body axes that span the face (drop the axis the
        // normal points along), so a face lying exactly on a cell boundary
        // does not flicker between tones.
        let a = abs(in.body_normal);
        var uv: vec2<f32>;
        if a.x >= a.y && a.x >= a.z {
            uv = in.body_pos.yz;
        } else if a.y >= a.z {
            uv = in.body_pos.xz;
        } else {
            uv = in.body_pos.xy;
        }
        let c = vec2<i32>(floor(uv / in.cell));
        if ((c.x + c.y) & 1) == 1 {
            base = base * checker_darken;
        }
    }
    let ambient = globals.light.w;
    let lambert = max(dot(n, globals.light.xyz), 0.0);
    return vec4<f32>(base * (ambient + (1.0 - ambient) * lambert), 1.0);
}
