//! `instantmimic gpu`: what the GPU and driver are, and whether they can run this program.

use anyhow::{Context, Result};
use clap::Args;

use crate::cuda::Gpu;

#[derive(Args, Debug)]
pub struct GpuArgs {
    /// CUDA device ordinal.
    #[arg(long, default_value_t = 0)]
    pub device: usize,
}

/// Prints the device facts; fails with one line when there is no usable driver or device.
pub fn run(args: &GpuArgs) -> Result<()> {
    let gpu =
        Gpu::open(args.device).with_context(|| format!("opening CUDA device {}", args.device))?;
    let info = gpu.info();
    let (cc_major, cc_minor) = info.compute_capability;
    println!("device             {} ({})", info.ordinal, info.name);
    println!("compute capability {cc_major}.{cc_minor} (sm_{cc_major}{cc_minor})");
    println!("multiprocessors    {}", info.sm_count);
    println!(
        "memory             {:.1} GiB",
        info.total_memory_bytes as f64 / (1u64 << 30) as f64
    );
    println!(
        "driver             CUDA {}.{} ({})",
        info.driver_version / 1000,
        (info.driver_version % 1000) / 10,
        info.driver_version
    );
    println!("max PTX ISA        {}", info.max_ptx_isa);
    Ok(())
}
