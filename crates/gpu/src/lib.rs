//! GPU access for hullcut on wgpu: adapter selection, device limits checked up front, storage
//! buffers, compute pipelines, and read-back with bounded waits.
//!
//! A hardware adapter is preferred (discrete, then integrated, then virtual); the environment
//! variable `HULLCUT_GPU_ADAPTER` forces the software adapter (`software`: Mesa's lavapipe, which
//! wgpu reports as [`wgpu::DeviceType::Cpu`]) or one whose name contains the given text. No adapter
//! is a clear [`GpuError`], never a silent fall back; [`for_tests`] turns it into a test failure
//! when `CI` is set.

use std::sync::mpsc;
use std::time::Duration;

use bytemuck::Pod;
use wgpu::util::DeviceExt as _;

/// The environment variable that chooses the adapter (see [`AdapterChoice::from_env`]).
pub const ADAPTER_ENV: &str = "HULLCUT_GPU_ADAPTER";

/// Longest wait for the device in one poll before a read-back is reported as timed out.
pub const POLL_TIMEOUT: Duration = Duration::from_secs(60);

/// What went wrong with the GPU.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// wgpu found no adapter at all.
    #[error(
        "no GPU adapter found: wgpu saw no Vulkan, Metal or DX12 device (on Debian, \
         `apt install mesa-vulkan-drivers` provides the software adapter, lavapipe)"
    )]
    NoAdapter,
    /// No adapter matches the requested one.
    #[error("no GPU adapter matches {wanted:?} (from {ADAPTER_ENV}); found: {found}")]
    NoMatch {
        /// What was asked for.
        wanted: String,
        /// The adapters there are, by name and type.
        found: String,
    },
    /// The adapter refused to open a device.
    #[error("opening a device on {adapter}: {message}")]
    Device {
        /// The adapter's name.
        adapter: String,
        /// wgpu's reason.
        message: String,
    },
    /// The device's limits are too small for the job.
    #[error("{what} needs {needed} bytes in one storage buffer; {adapter} allows {limit}")]
    Limits {
        /// What the buffer holds.
        what: String,
        /// Bytes needed.
        needed: u64,
        /// The device's limit.
        limit: u64,
        /// The adapter's name.
        adapter: String,
    },
    /// The device did not finish in time, or was lost.
    #[error("waiting for the GPU ({what}): {message}")]
    Wait {
        /// What was being read back.
        what: String,
        /// Why the wait ended.
        message: String,
    },
}

/// Which adapter to use.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AdapterChoice {
    /// The best hardware adapter, else the software one.
    Auto,
    /// A software adapter (wgpu's [`wgpu::DeviceType::Cpu`], lavapipe on Linux).
    Software,
    /// The first adapter whose name contains this text (case-insensitive).
    Named(String),
}

impl AdapterChoice {
    /// From [`ADAPTER_ENV`]: unset, empty or `auto` → [`AdapterChoice::Auto`]; `software` or `cpu`
    /// → [`AdapterChoice::Software`]; anything else names an adapter.
    pub fn from_env() -> Self {
        match std::env::var(ADAPTER_ENV) {
            Ok(v) => Self::parse(&v),
            Err(_) => Self::Auto,
        }
    }

    /// The choice written as in [`ADAPTER_ENV`].
    pub fn parse(text: &str) -> Self {
        match text.trim().to_ascii_lowercase().as_str() {
            "" | "auto" => Self::Auto,
            "software" | "cpu" => Self::Software,
            _ => Self::Named(text.trim().to_owned()),
        }
    }
}

/// An adapter as `hullcut gpu-info` shows it.
#[derive(Debug, Clone)]
pub struct AdapterSummary {
    /// wgpu's description.
    pub info: wgpu::AdapterInfo,
    /// Its limits.
    pub limits: wgpu::Limits,
    /// Whether it can time compute passes.
    pub timestamps: bool,
}

impl AdapterSummary {
    fn of(adapter: &wgpu::Adapter) -> Self {
        Self {
            info: adapter.get_info(),
            limits: adapter.limits(),
            timestamps: adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY),
        }
    }
}

fn instance() -> wgpu::Instance {
    wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env())
}

/// Every adapter wgpu finds, in the order [`AdapterChoice::Auto`] prefers them.
pub fn adapters() -> Vec<AdapterSummary> {
    let mut all: Vec<AdapterSummary> = pollster::block_on(instance().enumerate_adapters(wgpu::Backends::all()))
        .iter()
        .map(AdapterSummary::of)
        .collect();
    all.sort_by_key(|a| preference(a.info.device_type));
    all
}

/// Lower is preferred.
fn preference(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

/// An open device and its queue.
#[derive(Debug)]
pub struct Gpu {
    /// The adapter in use.
    pub summary: AdapterSummary,
    /// The device, opened with the adapter's own limits.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
}

impl Gpu {
    /// Opens the adapter `choice` asks for.
    pub fn new(choice: &AdapterChoice) -> Result<Self, GpuError> {
        let mut found = pollster::block_on(instance().enumerate_adapters(wgpu::Backends::all()));
        if found.is_empty() {
            return Err(GpuError::NoAdapter);
        }
        found.sort_by_key(|a| preference(a.get_info().device_type));
        let pick = match choice {
            AdapterChoice::Auto => Some(0),
            AdapterChoice::Software => found.iter().position(|a| a.get_info().device_type == wgpu::DeviceType::Cpu),
            AdapterChoice::Named(name) => {
                let name = name.to_lowercase();
                found.iter().position(|a| a.get_info().name.to_lowercase().contains(&name))
            }
        };
        let Some(pick) = pick else {
            let list: Vec<String> =
                found.iter().map(|a| a.get_info()).map(|i| format!("{} ({:?})", i.name, i.device_type)).collect();
            let wanted = match choice {
                AdapterChoice::Named(n) => n.clone(),
                _ => "software".to_owned(),
            };
            return Err(GpuError::NoMatch { wanted, found: list.join(", ") });
        };
        let adapter = found.swap_remove(pick);
        let summary = AdapterSummary::of(&adapter);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("hullcut"),
            required_limits: summary.limits.clone(),
            required_features: if summary.timestamps {
                wgpu::Features::TIMESTAMP_QUERY
            } else {
                wgpu::Features::empty()
            },
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device { adapter: summary.info.name.clone(), message: e.to_string() })?;
        tracing::info!(adapter = %summary.info.name, kind = ?summary.info.device_type, backend = ?summary.info.backend, "GPU device open");
        Ok(Self { summary, device, queue })
    }

    /// Whether this is a software adapter.
    pub fn is_software(&self) -> bool {
        self.summary.info.device_type == wgpu::DeviceType::Cpu
    }

    /// Checks that `bytes` fit one storage buffer binding (and one buffer) on this device.
    pub fn check_storage(&self, what: &str, bytes: u64) -> Result<(), GpuError> {
        let limit = self.summary.limits.max_storage_buffer_binding_size.min(self.summary.limits.max_buffer_size);
        if bytes > limit {
            return Err(GpuError::Limits {
                what: what.to_owned(),
                needed: bytes,
                limit,
                adapter: self.summary.info.name.clone(),
            });
        }
        Ok(())
    }

    /// A storage buffer holding `data` (at least 4 bytes, as wgpu needs), which shaders may write
    /// and [`Gpu::read`] may copy out.
    pub fn storage<T: Pod>(&self, label: &str, data: &[T]) -> Result<wgpu::Buffer, GpuError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        self.check_storage(label, bytes.len() as u64)?;
        let padded;
        let contents = if bytes.len() < 4 {
            padded = [0u8; 4];
            &padded[..]
        } else {
            bytes
        };
        Ok(self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        }))
    }

    /// A uniform buffer holding `value`.
    pub fn uniform<T: Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::bytes_of(value),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        })
    }

    /// A compute pipeline from WGSL source and its entry point (bind group layouts derived from
    /// the shader).
    pub fn pipeline(&self, label: &str, wgsl: &str, entry: &str) -> wgpu::ComputePipeline {
        let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(wgsl.into()),
        });
        self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: None,
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
    }

    /// A bind group for group 0 of `pipeline`, binding `buffers` in order from binding 0.
    pub fn bind(&self, pipeline: &wgpu::ComputePipeline, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        })
    }

    /// A bind group for group 0 of `pipeline` with each buffer at its own binding number (for
    /// shaders whose bindings are not numbered from 0 without gaps: a binding the entry point
    /// does not use is left out of its derived layout).
    pub fn bind_numbered(&self, pipeline: &wgpu::ComputePipeline, buffers: &[(u32, &wgpu::Buffer)]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .map(|&(binding, b)| wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        })
    }

    /// Waits at most [`POLL_TIMEOUT`] for the work submitted so far to finish.
    pub fn wait(&self, what: &str) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::Wait { submission_index: None, timeout: Some(POLL_TIMEOUT) })
            .map(|_| ())
            .map_err(|e| GpuError::Wait { what: what.to_owned(), message: e.to_string() })
    }

    /// Copies the first `len` values of `buffer` back to the CPU, waiting at most
    /// [`POLL_TIMEOUT`] for the device.
    pub fn read<T: Pod>(&self, what: &str, buffer: &wgpu::Buffer, len: usize) -> Result<Vec<T>, GpuError> {
        let size = (len * size_of::<T>()) as u64;
        if size == 0 {
            return Ok(Vec::new());
        }
        // Copies are in whole 4-byte words.
        let padded = size.next_multiple_of(4);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("read-back"),
            size: padded,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(what) });
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, padded);
        self.queue.submit([encoder.finish()]);
        let (tx, rx) = mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            // The receiver only goes away when the wait below has already failed.
            let _ = tx.send(r);
        });
        let wait = |message: String| GpuError::Wait { what: what.to_owned(), message };
        self.device
            .poll(wgpu::PollType::Wait { submission_index: None, timeout: Some(POLL_TIMEOUT) })
            .map_err(|e| wait(e.to_string()))?;
        rx.recv_timeout(POLL_TIMEOUT)
            .map_err(|e| wait(format!("no answer from the mapping: {e}")))?
            .map_err(|e| wait(e.to_string()))?;
        let view = staging.get_mapped_range(..).map_err(|e| wait(e.to_string()))?;
        let out = bytemuck::cast_slice::<u8, T>(&view[..size as usize]).to_vec();
        drop(view);
        staging.unmap();
        Ok(out)
    }

    /// A timer of compute passes on the device, or `None` where the adapter cannot time them.
    pub fn pass_timer(&self) -> Option<PassTimer> {
        if !self.device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            return None;
        }
        let set = self.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass timer"),
            ty: wgpu::QueryType::Timestamp,
            count: 2,
        });
        let resolve = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pass timer"),
            size: 16,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Some(PassTimer { set, resolve, period_ns: f64::from(self.queue.get_timestamp_period()) })
    }

    /// Runs one compute pass of `pipeline` over `invocations` (workgroups of `workgroup`).
    pub fn dispatch(&self, pipeline: &wgpu::ComputePipeline, bind: &wgpu::BindGroup, invocations: u32, workgroup: u32) {
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass =
                encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind, &[]);
            pass.dispatch_workgroups(invocations.div_ceil(workgroup), 1, 1);
        }
        self.queue.submit([encoder.finish()]);
    }
}

/// Device time of a compute pass from timestamp queries ([`Gpu::pass_timer`]): the pass writes
/// a timestamp at its start and end ([`PassTimer::writes`]), the encoder resolves them
/// ([`PassTimer::resolve`]) and, once the work is done, [`PassTimer::elapsed_ns`] reads them.
#[derive(Debug)]
pub struct PassTimer {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    period_ns: f64,
}

impl PassTimer {
    /// The timestamp writes of the pass to time.
    pub fn writes(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    /// Resolves the timestamps (after the pass, in the same encoder).
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.set, 0..2, &self.resolve, 0);
    }

    /// Nanoseconds between the pass's start and end, once its submission is done.
    pub fn elapsed_ns(&self, gpu: &Gpu) -> Result<f64, GpuError> {
        let t: Vec<u64> = gpu.read("pass timestamps", &self.resolve, 2)?;
        Ok(t[1].saturating_sub(t[0]) as f64 * self.period_ns)
    }
}

/// The device for a GPU test: `Some` when one opens; otherwise the test fails when the
/// environment variable `CI` is set (CI has lavapipe, so a missing adapter is a broken setup) and
/// is skipped, saying so, when it is not.
///
/// # Panics
/// Without a device, when `CI` is set.
pub fn for_tests() -> Option<Gpu> {
    match Gpu::new(&AdapterChoice::from_env()) {
        Ok(gpu) => Some(gpu),
        Err(e) if std::env::var_os("CI").is_some() => panic!("CI has no usable GPU adapter: {e}"),
        Err(e) => {
            eprintln!("skipping a GPU test: {e}");
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adapter_choice_reads_as_documented() {
        assert_eq!(AdapterChoice::parse(""), AdapterChoice::Auto);
        assert_eq!(AdapterChoice::parse(" Auto "), AdapterChoice::Auto);
        assert_eq!(AdapterChoice::parse("software"), AdapterChoice::Software);
        assert_eq!(AdapterChoice::parse("CPU"), AdapterChoice::Software);
        assert_eq!(AdapterChoice::parse("llvmpipe"), AdapterChoice::Named("llvmpipe".into()));
    }

    #[test]
    fn a_buffer_round_trips_and_limits_are_checked() {
        let Some(gpu) = for_tests() else { return };
        let data: Vec<u32> = (0..1000).map(|i| i * 7 + 1).collect();
        let buffer = gpu.storage("round trip", &data).expect("buffer");
        assert_eq!(gpu.read::<u32>("round trip", &buffer, data.len()).expect("read"), data);
        let too_big = gpu.summary.limits.max_buffer_size.max(gpu.summary.limits.max_storage_buffer_binding_size) + 1;
        let err = gpu.check_storage("a huge lattice", too_big).expect_err("over the limit");
        assert!(err.to_string().contains("a huge lattice"), "{err}");
    }

    #[test]
    fn a_timed_pass_takes_time_where_the_adapter_has_timestamps() {
        let Some(gpu) = for_tests() else { return };
        let Some(timer) = gpu.pass_timer() else {
            assert!(!gpu.summary.timestamps, "the adapter has timestamps but no timer was made");
            return;
        };
        // A loop long enough to take measurable time.
        let wgsl = "@group(0) @binding(0) var<storage, read_write> v: array<f32>;\n\
                    @compute @workgroup_size(64) fn main(@builtin(global_invocation_id) g: vec3<u32>) {\n\
                        var x = v[g.x];\n\
                        for (var i = 0u; i < 2000u; i++) { x = x * 0.999 + 1.0; }\n\
                        v[g.x] = x;\n\
                    }\n";
        let pipeline = gpu.pipeline("spin", wgsl, "main");
        let buffer = gpu.storage("values", &vec![0.0f32; 64 * 256]).expect("buffer");
        let bind = gpu.bind(&pipeline, &[&buffer]);
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes: Some(timer.writes()),
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(256, 1, 1);
        }
        timer.resolve(&mut encoder);
        gpu.queue.submit([encoder.finish()]);
        let ns = timer.elapsed_ns(&gpu).expect("timestamps");
        assert!(ns > 0.0 && ns < 60e9, "{ns} ns");
    }

    #[test]
    fn a_kernel_runs() {
        let Some(gpu) = for_tests() else { return };
        let wgsl = "@group(0) @binding(0) var<storage, read_write> v: array<u32>;\n\
                    @compute @workgroup_size(64) fn main(@builtin(global_invocation_id) g: vec3<u32>) {\n\
                        if (g.x < arrayLength(&v)) { v[g.x] = v[g.x] * 3u + g.x; }\n\
                    }\n";
        let pipeline = gpu.pipeline("triple", wgsl, "main");
        let data: Vec<u32> = (0..300).collect();
        let buffer = gpu.storage("values", &data).expect("buffer");
        let bind = gpu.bind(&pipeline, &[&buffer]);
        gpu.dispatch(&pipeline, &bind, data.len() as u32, 64);
        let out = gpu.read::<u32>("values", &buffer, data.len()).expect("read");
        assert!(out.iter().enumerate().all(|(i, &x)| x == 4 * i as u32), "{:?}", &out[..8]);
    }
}
