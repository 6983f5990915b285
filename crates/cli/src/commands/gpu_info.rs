//! `hullcut gpu-info`: the GPU adapters wgpu finds, and the one hullcut would use.

use anyhow::Context as _;
use clap::Parser;
use hullcut_gpu::{ADAPTER_ENV, AdapterChoice, Gpu, GpuError};

/// Lists the GPU adapters wgpu finds (Vulkan, Metal, DX12) and opens the one hullcut would use: the
/// best hardware adapter, else the software one. The environment variable HULLCUT_GPU_ADAPTER
/// chooses: `software` for a software adapter (Mesa's lavapipe, from Debian's mesa-vulkan-drivers),
/// or part of an adapter's name. Fails (exit 1) when there is none.
#[derive(Debug, Parser)]
pub struct Args {}

/// Runs the command.
pub fn run(_args: &Args) -> anyhow::Result<()> {
    let all = hullcut_gpu::adapters();
    if all.is_empty() {
        return Err(GpuError::NoAdapter.into());
    }
    println!("{} adapter(s), in the order hullcut prefers them:", all.len());
    for a in &all {
        let i = &a.info;
        println!("  {} ({:?}, {:?}; driver {} {})", i.name, i.device_type, i.backend, i.driver, i.driver_info);
    }
    let choice = AdapterChoice::from_env();
    let gpu = Gpu::new(&choice).with_context(|| format!("opening the adapter {ADAPTER_ENV} chooses"))?;
    let (i, l) = (&gpu.summary.info, &gpu.summary.limits);
    println!("using {} ({:?}, {:?}) for {choice:?}", i.name, i.device_type, i.backend);
    println!(
        "  storage buffer binding up to {} MiB, buffers up to {} MiB; workgroups up to {} invocations \
         ({} along x), {} per dimension; timestamp queries: {}",
        l.max_storage_buffer_binding_size >> 20,
        l.max_buffer_size >> 20,
        l.max_compute_invocations_per_workgroup,
        l.max_compute_workgroup_size_x,
        l.max_compute_workgroups_per_dimension,
        if gpu.summary.timestamps { "yes" } else { "no" }
    );
    Ok(())
}
