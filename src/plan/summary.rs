//! A plan at a glance: what `instantmimic plan inspect` prints (as text or JSON). The op
//! counts match `tools/wrp_inspect.py`: by kind and nesting depth.

use std::collections::BTreeMap;
use std::fmt;

use serde::Serialize;

use super::model::Plan;
use super::ops::walk_ops;

/// Counts and sizes of one plan.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlanSummary {
    /// From [`super::PlanInfo`]; `None` for a plan straight from Warp.
    pub name: Option<String>,
    pub nworld: Option<u32>,
    pub physics: Option<serde_json::Map<String, serde_json::Value>>,
    pub device: String,
    pub target_arch: u32,
    pub producer: String,
    pub modules: usize,
    pub kernels: usize,
    /// Kernel-table block_dim -> number of kernels.
    pub kernel_block_dims: BTreeMap<u32, usize>,
    pub top_level_ops: usize,
    /// Op kind -> count over the whole tree (nested ops included).
    pub op_counts: BTreeMap<String, usize>,
    /// Per nesting depth (0 = top level): op kind -> count.
    pub op_counts_by_depth: Vec<BTreeMap<String, usize>>,
    pub regions: usize,
    pub region_bytes: u64,
    pub initial_data_bytes: u64,
    /// Named bindings, sorted by name.
    pub bindings: Vec<BindingSummary>,
}

/// One named binding.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct BindingSummary {
    pub name: String,
    pub region: u32,
    /// Size of the region (0 if the region is missing, which a parsed plan rules out).
    pub bytes: u64,
}

impl PlanSummary {
    pub fn of(plan: &Plan) -> Self {
        let mut kernel_block_dims = BTreeMap::new();
        for kernel in &plan.kernels {
            *kernel_block_dims.entry(kernel.block_dim).or_insert(0) += 1;
        }
        let mut op_counts = BTreeMap::new();
        let mut op_counts_by_depth: Vec<BTreeMap<String, usize>> = Vec::new();
        walk_ops(&plan.ops, &mut |op, depth| {
            let name = op.kind().name().to_string();
            *op_counts.entry(name.clone()).or_insert(0) += 1;
            if op_counts_by_depth.len() <= depth {
                op_counts_by_depth.resize_with(depth + 1, BTreeMap::new);
            }
            if let Some(level) = op_counts_by_depth.get_mut(depth) {
                *level.entry(name).or_insert(0) += 1;
            }
        });
        let mut bindings: Vec<BindingSummary> = plan
            .bindings
            .iter()
            .map(|b| BindingSummary {
                name: b.name.clone(),
                region: b.region,
                bytes: plan.region(b.region).map_or(0, |r| r.size),
            })
            .collect();
        bindings.sort_by(|a, b| a.name.cmp(&b.name));
        let info = plan.info();
        PlanSummary {
            name: info.map(|i| i.name.clone()),
            nworld: info.map(|i| i.nworld),
            physics: info.map(|i| i.physics.clone()),
            device: plan.header.device.name().to_string(),
            target_arch: plan.header.target_arch,
            producer: plan.producer.clone(),
            modules: plan.modules.len(),
            kernels: plan.kernels.len(),
            kernel_block_dims,
            top_level_ops: plan.ops.len(),
            op_counts,
            op_counts_by_depth,
            regions: plan.regions.len(),
            region_bytes: plan.regions.iter().map(|r| r.size).sum(),
            initial_data_bytes: plan
                .regions
                .iter()
                .filter_map(|r| r.initial_data.as_ref())
                .map(|d| d.len() as u64)
                .sum(),
            bindings,
        }
    }
}

impl fmt::Display for PlanSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let unknown = || "unknown".to_string();
        writeln!(f, "name     {}", self.name.clone().unwrap_or_else(unknown))?;
        writeln!(
            f,
            "nworld   {}",
            self.nworld.map_or_else(unknown, |n| n.to_string())
        )?;
        let arch = if self.target_arch == 0 {
            String::new()
        } else {
            format!(" sm_{}", self.target_arch)
        };
        writeln!(
            f,
            "device   {}{arch} (captured by warp {})",
            self.device, self.producer
        )?;
        writeln!(f, "modules  {}", self.modules)?;
        writeln!(f, "kernels  {}", self.kernels)?;
        let dims: Vec<String> = self
            .kernel_block_dims
            .iter()
            .map(|(dim, n)| format!("{dim}: {n}"))
            .collect();
        writeln!(f, "kernel block dims  {{{}}}", dims.join(", "))?;
        writeln!(f, "ops      {} at top level", self.top_level_ops)?;
        for (depth, counts) in self.op_counts_by_depth.iter().enumerate() {
            for (kind, n) in counts {
                let indent = "  ".repeat(depth + 1);
                writeln!(f, "{indent}{kind:<24} {n}")?;
            }
        }
        writeln!(
            f,
            "regions  {}: {} bytes, {} with initial data",
            self.regions, self.region_bytes, self.initial_data_bytes
        )?;
        writeln!(f, "bindings {}", self.bindings.len())?;
        for b in &self.bindings {
            writeln!(
                f,
                "  {:<32} region {:<6} {} bytes",
                b.name, b.region, b.bytes
            )?;
        }
        Ok(())
    }
}
