use std::ops::Range;
use std::sync::mpsc;

use bytemuck::{Pod, Zeroable};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::camera::{Camera, look_at_scene};
use super::mesh::{Mesh, Vertex, flatten};
use super::{BACKGROUND, FIXED_CHECKER_DARKEN, Image, Instance, RenderError};

/// Plain UNORM, no sRGB step: instance colours and [`BACKGROUND`] come out
/// as the bytes they name, which keeps the clear colour exact.
const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Share of a body's colour that faces turned away from the key light keep,
/// enough to read their shape against the background.
const AMBIENT: f32 = 0.3;
/// Multisampling on real GPUs, where it is nearly free. Not on CPU adapters
/// (lavapipe, llvmpipe): there it multiplies the frame time, and the
/// render rank must keep up with the simulation.
const MSAA_SAMPLES: u32 = 4;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Globals {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    light: [f32; 4],
}

/// Per-body data, one vertex-buffer element with instance step; vec4s only
/// so the layout needs no padding rules.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct InstanceRaw {
    rotation: [f32; 4],
    translation_cell: [f32; 4],
    color: [f32; 4],
}

const INSTANCE_SIZE: u64 = std::mem::size_of::<InstanceRaw>() as u64;

struct MeshSlot {
    vertices: Range<u32>,
    closed: bool,
    radius: f32,
    bounds: [[f32; 3]; 2],
    checker_cell: f32,
}

/// Headless wgpu renderer: meshes uploaded once, then one call to
/// [`Renderer::render`] per frame with every body's pose.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter_info: String,
    width: u32,
    height: u32,
    /// For closed meshes, wound outward by `mesh::flatten`.
    culled: wgpu::RenderPipeline,
    /// For open meshes, whose outside is unknown.
    two_sided: wgpu::RenderPipeline,
    sample_count: u32,
    globals: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// All meshes' flat vertices back to back; `None` when there are none.
    vertices: Option<wgpu::Buffer>,
    meshes: Vec<MeshSlot>,
    instances: wgpu::Buffer,
    instance_capacity: u64,
    /// Reused each frame: instances grouped by mesh, and each mesh's range.
    staged: Vec<InstanceRaw>,
    groups: Vec<Range<u32>>,
    /// Multisampled colour target; `None` without MSAA.
    msaa_view: Option<wgpu::TextureView>,
    resolved: wgpu::Texture,
    resolved_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    /// Bytes per row in `readback`: `width * 4` rounded up to 256, the
    /// alignment texture-to-buffer copies require.
    padded_row: u32,
}

impl Renderer {
    /// Opens a GPU (a real one if present, else Mesa's lavapipe or llvmpipe)
    /// and uploads `meshes`; [`Instance::mesh`] indexes this list.
    pub fn new(width: u32, height: u32, meshes: Vec<Mesh>) -> Result<Renderer, RenderError> {
        let bad_size = |reason: String| RenderError::BadSize {
            width,
            height,
            reason,
        };
        if width == 0 || height == 0 {
            return Err(bad_size("both sides must be at least 1".into()));
        }
        let flat = meshes
            .iter()
            .enumerate()
            .map(|(i, m)| flatten(i, m))
            .collect::<Result<Vec<_>, _>>()?;

        // Only Vulkan and GL: asking for every backend would also start an
        // EGL context (more threads) even when Vulkan wins.
        // `WGPU_BACKEND=gl` still forces the GL path for a check.
        let instance = wgpu::Instance::new(
            wgpu::InstanceDescriptor {
                backends: wgpu::Backends::VULKAN | wgpu::Backends::GL,
                ..wgpu::InstanceDescriptor::new_without_display_handle()
            }
            .with_env(),
        );
        // force_fallback_adapter would skip a real GPU; HighPerformance
        // ranks discrete, then integrated, then CPU adapters.
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            apply_limit_buckets: false,
        }))
        .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let adapter_info = if info.driver_info.is_empty() {
            format!("{} ({:?})", info.name, info.backend)
        } else {
            format!("{} ({:?}, {})", info.name, info.backend, info.driver_info)
        };

        let limits = adapter.limits();
        let max_side = limits.max_texture_dimension_2d;
        if width > max_side || height > max_side {
            return Err(bad_size(format!(
                "{adapter_info} allows at most {max_side} pixels a side"
            )));
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("rigidsim render"),
            required_features: wgpu::Features::empty(),
            required_limits: limits,
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| RenderError::RequestDevice {
            adapter: adapter_info.clone(),
            message: e.to_string(),
        })?;

        let msaa_ok = |format| {
            adapter
                .get_texture_format_features(format)
                .flags
                .sample_count_supported(MSAA_SAMPLES)
        };
        let sample_count = if info.device_type != wgpu::DeviceType::Cpu
            && msaa_ok(COLOR_FORMAT)
            && msaa_ok(DEPTH_FORMAT)
        {
            MSAA_SAMPLES
        } else {
            1
        };

        gpu_scope(&device, "creating the renderer", || {
            Ok(Self::build(
                device.clone(),
                queue.clone(),
                adapter_info.clone(),
                width,
                height,
                sample_count,
                &flat,
            ))
        })
    }

    fn build(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter_info: String,
        width: u32,
        height: u32,
        sample_count: u32,
        flat: &[super::mesh::FlatMesh],
    ) -> Renderer {
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("render/shader.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shader.wgsl").into()),
        });
        let globals = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("globals"),
            size: std::mem::size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("globals"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("globals"),
            layout: &bind_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: globals.as_entire_binding(),
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("bodies"),
            bind_group_layouts: &[Some(&bind_layout)],
            immediate_size: 0,
        });
        let culled = body_pipeline(
            &device,
            &layout,
            &shader,
            sample_count,
            Some(wgpu::Face::Back),
        );
        let two_sided = body_pipeline(&device, &layout, &shader, sample_count, None);

        let mut all_vertices = Vec::new();
        let meshes = flat
            .iter()
            .map(|m| {
                let start = all_vertices.len() as u32;
                all_vertices.extend_from_slice(&m.vertices);
                MeshSlot {
                    vertices: start..all_vertices.len() as u32,
                    closed: m.closed,
                    radius: m.radius,
                    bounds: m.bounds,
                    checker_cell: m.checker_cell,
                }
            })
            .collect();
        let vertices = (!all_vertices.is_empty()).then(|| {
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("mesh vertices"),
                size: std::mem::size_of_val(all_vertices.as_slice()) as u64,
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            queue.write_buffer(&buffer, 0, bytemuck::cast_slice(&all_vertices));
            buffer
        });

        let instance_capacity = 256;
        let instances = instance_buffer(&device, instance_capacity);

        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let target = |label, format, samples, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let resolved = target(
            "frame",
            COLOR_FORMAT,
            1,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let resolved_view = resolved.create_view(&Default::default());
        let msaa_view = (sample_count > 1).then(|| {
            target(
                "frame msaa",
                COLOR_FORMAT,
                sample_count,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            )
            .create_view(&Default::default())
        });
        let depth_view = target(
            "depth",
            DEPTH_FORMAT,
            sample_count,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        )
        .create_view(&Default::default());

        let padded_row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame readback"),
            size: u64::from(padded_row) * u64::from(height),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });

        Renderer {
            device,
            queue,
            adapter_info,
            width,
            height,
            culled,
            two_sided,
            sample_count,
            globals,
            bind_group,
            vertices,
            meshes,
            instances,
            instance_capacity,
            staged: Vec::new(),
            groups: Vec::new(),
            msaa_view,
            resolved,
            resolved_view,
            depth_view,
            readback,
            padded_row,
        }
    }

    /// Adapter name, backend and driver for the run summary, e.g.
    /// `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Mesa 22.3.6 (LLVM 15.0.6))`.
    pub fn adapter_info(&self) -> String {
        self.adapter_info.clone()
    }

    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Samples per pixel: 4 on GPUs, 1 on CPU adapters (see MSAA_SAMPLES).
    pub fn sample_count(&self) -> u32 {
        self.sample_count
    }

    /// [`look_at_scene`] over the corners of every body's box (its mesh's
    /// body-frame bounding box, posed), for scenes that give no camera.
    pub fn look_at_instances(&self, instances: &[Instance]) -> Camera {
        let mut points = Vec::with_capacity(instances.len() * 8);
        for inst in instances.iter().filter(|i| i.mesh < self.meshes.len()) {
            let [lo, hi] = self.meshes[inst.mesh].bounds;
            let [w, x, y, z] = inst.rotation;
            let rotation = UnitQuaternion::try_new(Quaternion::new(w, x, y, z), 1e-12)
                .unwrap_or_else(UnitQuaternion::identity);
            let translation = Vector3::from(inst.translation);
            for i in 0..8 {
                let corner = Vector3::from(std::array::from_fn(|k| {
                    if i >> k & 1 == 0 { lo[k] } else { hi[k] }
                }));
                points.push((rotation * corner + translation).into());
            }
        }
        look_at_scene(&points)
    }

    /// Draws one frame and reads it back. Blocks until the GPU is done.
    pub fn render(
        &mut self,
        camera: &Camera,
        instances: &[Instance],
    ) -> Result<Image, RenderError> {
        let basis = camera.basis()?;
        self.stage_instances(instances)?;
        let (near, far) = self.depth_range(&basis.eye, instances);
        let aspect = self.width as f32 / self.height as f32;
        let view_proj = basis.view_projection(camera.fov_y_deg, aspect, near, far);
        let globals = Globals {
            view_proj: view_proj.into(),
            eye: basis.eye.push(1.0).into(),
            light: basis.key_light().push(AMBIENT).into(),
        };
        let device = self.device.clone();
        gpu_scope(&device, "rendering a frame", || {
            self.queue
                .write_buffer(&self.globals, 0, bytemuck::bytes_of(&globals));
            self.upload_instances();
            self.draw_and_copy();
            self.read_back()
        })
    }

    /// Validates instances and groups them by mesh with a counting sort, so
    /// each mesh is one instanced draw over a contiguous range.
    fn stage_instances(&mut self, instances: &[Instance]) -> Result<(), RenderError> {
        let mesh_count = self.meshes.len();
        let mut counts = vec![0u32; mesh_count];
        for (i, inst) in instances.iter().enumerate() {
            if inst.mesh >= mesh_count {
                return Err(RenderError::UnknownMesh {
                    instance: i,
                    mesh: inst.mesh,
                    mesh_count,
                });
            }
            let finite = inst
                .rotation
                .iter()
                .chain(&inst.translation)
                .chain(&inst.color)
                .all(|v| v.is_finite());
            if !finite {
                return Err(RenderError::BadInstance {
                    instance: i,
                    reason: format!("non-finite value in {inst:?}"),
                });
            }
            counts[inst.mesh] += 1;
        }
        self.groups.clear();
        let mut next = Vec::with_capacity(mesh_count);
        let mut start = 0;
        for &count in &counts {
            self.groups.push(start..start + count);
            next.push(start as usize);
            start += count;
        }
        self.staged.clear();
        self.staged.resize(instances.len(), InstanceRaw::zeroed());
        for inst in instances {
            let slot = &mut next[inst.mesh];
            self.staged[*slot] = self.raw_instance(inst);
            *slot += 1;
        }
        Ok(())
    }

    fn raw_instance(&self, inst: &Instance) -> InstanceRaw {
        let [w, x, y, z] = inst.rotation;
        let norm = (w * w + x * x + y * y + z * z).sqrt();
        let rotation = if norm > 1e-12 {
            [x / norm, y / norm, z / norm, w / norm]
        } else {
            [0.0, 0.0, 0.0, 1.0]
        };
        let [tx, ty, tz] = inst.translation;
        let cell = if inst.fixed {
            self.meshes[inst.mesh].checker_cell
        } else {
            0.0
        };
        let [r, g, b] = inst.color.map(|c| c.clamp(0.0, 1.0));
        InstanceRaw {
            rotation,
            translation_cell: [tx, ty, tz, cell],
            color: [r, g, b, 1.0],
        }
    }

    /// Near and far planes that just enclose the bodies' bounding spheres as
    /// seen from `eye`. With reversed Z a near plane 1e-4 of the far one
    /// still leaves ample depth precision, so an eye inside the scene is fine.
    fn depth_range(&self, eye: &Vector3<f32>, instances: &[Instance]) -> (f32, f32) {
        let mut bounds: Option<(Vector3<f32>, Vector3<f32>)> = None;
        for inst in instances {
            let r = Vector3::repeat(self.meshes[inst.mesh].radius);
            let p = Vector3::from(inst.translation);
            let (lo, hi) = bounds.unwrap_or((p, p));
            bounds = Some((lo.inf(&(p - r)), hi.sup(&(p + r))));
        }
        let Some((lo, hi)) = bounds else {
            return (0.1, 100.0);
        };
        let centre = (lo + hi) * 0.5;
        let radius = (hi - lo).norm() * 0.5;
        let distance = (centre - eye).norm();
        // 1% slack so bodies grazing the sphere are not clipped by rounding.
        let far = ((distance + radius) * 1.01).max(1e-3);
        let near = ((distance - radius) * 0.99).max(far * 1e-4);
        (near, far)
    }

    fn upload_instances(&mut self) {
        let needed = self.staged.len() as u64;
        if needed > self.instance_capacity {
            self.instance_capacity = needed.next_power_of_two();
            self.instances = instance_buffer(&self.device, self.instance_capacity);
        }
        if !self.staged.is_empty() {
            self.queue
                .write_buffer(&self.instances, 0, bytemuck::cast_slice(&self.staged));
        }
    }

    fn draw_and_copy(&mut self) {
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        {
            let [r, g, b, a] = BACKGROUND.map(|c| f64::from(c) / 255.0);
            let (view, resolve_target) = match &self.msaa_view {
                Some(msaa) => (msaa, Some(&self.resolved_view)),
                None => (&self.resolved_view, None),
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("bodies"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a }),
                        // The multisampled samples are not needed after the
                        // resolve.
                        store: if resolve_target.is_some() {
                            wgpu::StoreOp::Discard
                        } else {
                            wgpu::StoreOp::Store
                        },
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            if let Some(vertices) = &self.vertices {
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.set_vertex_buffer(0, vertices.slice(..));
                for (mesh, group) in self.meshes.iter().zip(&self.groups) {
                    if group.is_empty() || mesh.vertices.is_empty() {
                        continue;
                    }
                    pass.set_pipeline(if mesh.closed {
                        &self.culled
                    } else {
                        &self.two_sided
                    });
                    // The instance range goes through the buffer offset, not
                    // `first_instance`, which GLES lacks natively.
                    let bytes = u64::from(group.start) * INSTANCE_SIZE
                        ..u64::from(group.end) * INSTANCE_SIZE;
                    pass.set_vertex_buffer(1, self.instances.slice(bytes));
                    pass.draw(mesh.vertices.clone(), 0..group.len() as u32);
                }
            }
        }
        encoder.copy_texture_to_buffer(
            self.resolved.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.padded_row),
                    rows_per_image: Some(self.height),
                },
            },
            self.resolved.size(),
        );
        self.queue.submit([encoder.finish()]);
    }

    fn read_back(&self) -> Result<Image, RenderError> {
        let gpu_err = |message: String| RenderError::Gpu {
            stage: "reading a frame back",
            message,
        };
        let slice = self.readback.slice(..);
        let (tx, rx) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| gpu_err(e.to_string()))?;
        rx.recv()
            .map_err(|_| gpu_err("map callback never ran".into()))?
            .map_err(|e| gpu_err(e.to_string()))?;

        let row = self.width as usize * 4;
        let mut rgba = Vec::with_capacity(row * self.height as usize);
        {
            let mapped = slice
                .get_mapped_range()
                .map_err(|e| gpu_err(e.to_string()))?;
            for padded in mapped.chunks(self.padded_row as usize) {
                rgba.extend_from_slice(&padded[..row]);
            }
        }
        self.readback.unmap();
        Ok(Image {
            width: self.width,
            height: self.height,
            rgba,
        })
    }
}

fn body_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    shader: &wgpu::ShaderModule,
    sample_count: u32,
    cull_mode: Option<wgpu::Face>,
) -> wgpu::RenderPipeline {
    let vertex_attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
    let instance_attributes =
        wgpu::vertex_attr_array![2 => Float32x4, 3 => Float32x4, 4 => Float32x4];
    let constants = [("checker_darken", f64::from(FIXED_CHECKER_DARKEN))];
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(if cull_mode.is_some() {
            "closed bodies"
        } else {
            "open bodies"
        }),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module: shader,
            entry_point: Some("vs_main"),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &constants,
                ..Default::default()
            },
            buffers: &[
                Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<Vertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &vertex_attributes,
                }),
                Some(wgpu::VertexBufferLayout {
                    array_stride: INSTANCE_SIZE,
                    step_mode: wgpu::VertexStepMode::Instance,
                    attributes: &instance_attributes,
                }),
            ],
        },
        primitive: wgpu::PrimitiveState {
            front_face: wgpu::FrontFace::Ccw,
            cull_mode,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: wgpu::StencilState::default(),
            bias: wgpu::DepthBiasState::default(),
        }),
        multisample: wgpu::MultisampleState {
            count: sample_count,
            ..Default::default()
        },
        fragment: Some(wgpu::FragmentState {
            module: shader,
            entry_point: Some("fs_main"),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &constants,
                ..Default::default()
            },
            targets: &[Some(wgpu::ColorTargetState {
                format: COLOR_FORMAT,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

fn instance_buffer(device: &wgpu::Device, capacity: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("instances"),
        size: capacity * INSTANCE_SIZE,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Runs `f` inside validation and out-of-memory error scopes, so a wgpu
/// error comes back as [`RenderError::Gpu`] instead of wgpu's default
/// handler, which panics.
fn gpu_scope<T>(
    device: &wgpu::Device,
    stage: &'static str,
    f: impl FnOnce() -> Result<T, RenderError>,
) -> Result<T, RenderError> {
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let result = f();
    let validation = pollster::block_on(validation.pop());
    let oom = pollster::block_on(oom.pop());
    match validation.or(oom) {
        Some(e) => Err(RenderError::Gpu {
            stage,
            message: e.to_string(),
        }),
        None => result,
    }
}
