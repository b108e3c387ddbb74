//! Generates `$OUT_DIR/env_kernels.rs` from a validated `ptx/env/manifest.json`: one typed
//! launcher per kernel, the ABI constants they pack with, and a Rust struct per Warp struct.
//! The output is included by `src/kernels/launchers.rs`, whose imports it uses (`ArgBuffer`,
//! `KernelAbi`, `DeviceArray`, ...). Part of `build.rs` (`#[path]`), std only besides the
//! manifest module.

use std::fmt::Write as _;

use crate::manifest::{
    Dtype, EnvManifest, Io, KernelDef, ModuleDef, Op, Rule, Slot, SlotType, rust_ident,
};

/// A manifest the generator cannot turn into Rust; the message says where and why.
#[derive(Debug)]
pub struct CodegenError(pub String);

impl std::fmt::Display for CodegenError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

fn ident(name: &str, place: &str) -> Result<String, CodegenError> {
    rust_ident(name)
        .ok_or_else(|| CodegenError(format!("{place}: {name:?} is not a Rust identifier")))
}

/// `SHOUTING_CASE` of a snake_case kernel name, for its ABI constant.
fn const_name(kernel: &str) -> String {
    kernel.to_ascii_uppercase()
}

fn str_lit(s: &str) -> String {
    format!("{s:?}")
}

fn shape_lit(shape: &[usize]) -> String {
    let items: Vec<String> = shape.iter().map(ToString::to_string).collect();
    format!("&[{}]", items.join(", "))
}

fn doc_lines(out: &mut String, indent: &str, text: &str) {
    for line in text.lines() {
        if line.trim().is_empty() {
            let _ = writeln!(out, "{indent}///");
        } else {
            let _ = writeln!(out, "{indent}/// {line}");
        }
    }
}

/// The Rust type a launcher takes for a parameter.
fn param_type(slot: &Slot) -> String {
    match &slot.ty {
        SlotType::Value(dtype) => dtype.rust_type(),
        SlotType::Array { dtype, ndim } => format!("&DeviceArray<{}, {ndim}>", dtype.rust_type()),
        SlotType::Struct(name) => format!("&{name}"),
    }
}

fn param_kind(slot: &Slot) -> String {
    let value = |d: &Dtype| {
        format!(
            "scalar: ScalarType::{}, shape: {}",
            d.scalar.variant(),
            shape_lit(&d.shape)
        )
    };
    match &slot.ty {
        SlotType::Value(d) => format!("ParamKind::Value {{ {} }}", value(d)),
        SlotType::Array { dtype, ndim } => {
            format!("ParamKind::Array {{ {}, ndim: {ndim} }}", value(dtype))
        }
        SlotType::Struct(name) => format!("ParamKind::Struct {{ name: {} }}", str_lit(name)),
    }
}

fn write_struct(
    out: &mut String,
    name: &str,
    fields: &[Slot],
    size: usize,
) -> Result<(), CodegenError> {
    let place = format!("struct {name}");
    let _ = writeln!(
        out,
        "/// Warp struct `{name}` ({size} bytes), passed by value to the kernels that take it.\n\
         #[derive(Debug, Clone, Copy, Default, PartialEq)]\npub struct {name} {{"
    );
    for f in fields {
        let field = ident(&f.name, &place)?;
        let ty = match &f.ty {
            SlotType::Value(dtype) => dtype.rust_type(),
            SlotType::Struct(inner) => inner.clone(),
            SlotType::Array { .. } => {
                return Err(CodegenError(format!(
                    "{place}, field {}: array fields in struct parameters are not supported by the launcher generator yet (build/env_codegen.rs); pass the array as its own kernel parameter",
                    f.name
                )));
            }
        };
        let _ = writeln!(out, "    pub {field}: {ty},");
    }
    let _ = writeln!(
        out,
        "}}\n\nimpl WarpStruct for {name} {{\n    const NAME: &'static str = {};\n    const SIZE: usize = {size};\n    fn write_le(&self, out: &mut [u8]) {{",
        str_lit(name)
    );
    if fields.is_empty() {
        let _ = writeln!(out, "        let _ = out;");
    }
    for f in fields {
        let field = ident(&f.name, &place)?;
        let writer = match f.ty {
            SlotType::Struct(_) => "write_struct_field",
            _ => "write_field",
        };
        let _ = writeln!(out, "        {writer}(out, {}, &self.{field});", f.offset);
    }
    let _ = writeln!(out, "    }}\n}}\n");
    Ok(())
}

fn write_abi(out: &mut String, module: &ModuleDef, kernel: &KernelDef, rules: &[Rule]) {
    let _ = writeln!(
        out,
        "/// How the `{}` launcher packs its arguments (`{}`).\npub const {}: KernelAbi = KernelAbi {{\n    module: {},\n    ptx: {},\n    name: {},\n    entry: {},\n    dim: {},\n    block_dim: {},\n    smem_bytes: {},\n    params: &[",
        kernel.name,
        module.source,
        const_name(&kernel.name),
        str_lit(&module.name),
        str_lit(&module.ptx),
        str_lit(&kernel.name),
        str_lit(&kernel.entry),
        kernel.dim,
        kernel.block_dim,
        kernel.smem_bytes,
    );
    for p in &kernel.params {
        let _ = writeln!(
            out,
            "        ParamAbi {{ name: {}, kind: {}, offset: {}, size: {}, align: {}, io: Io::{} }},",
            str_lit(&p.name),
            param_kind(p),
            p.offset,
            p.size,
            p.align,
            p.io.unwrap_or(Io::In).variant()
        );
    }
    let _ = writeln!(out, "    ],\n    launch: &[");
    for rule in rules {
        let ops: Vec<String> = rule.bound.iter().map(Op::rust).collect();
        let _ = writeln!(
            out,
            "        LaunchRule {{ axis: {}, relation: Relation::{}, bound: &[{}], text: {} }},",
            rule.axis,
            rule.relation.variant(),
            ops.join(", "),
            str_lit(&rule.text)
        );
    }
    let _ = writeln!(out, "    ],\n}};\n");
}

/// "reads `a`, `b`; writes `c`; updates `d`" for a kernel's array parameters.
fn array_directions(kernel: &KernelDef) -> String {
    let names = |io: Io| -> Vec<String> {
        kernel
            .params
            .iter()
            .filter(|p| matches!(p.ty, SlotType::Array { .. }) && p.io == Some(io))
            .map(|p| format!("`{}`", p.name))
            .collect()
    };
    let parts: Vec<String> = [
        (Io::In, "reads"),
        (Io::Out, "writes"),
        (Io::InOut, "updates"),
    ]
    .into_iter()
    .filter_map(|(io, verb)| {
        let list = names(io);
        (!list.is_empty()).then(|| format!("{verb} {}", list.join(", ")))
    })
    .collect();
    if parts.is_empty() {
        "none".to_owned()
    } else {
        parts.join("; ")
    }
}

fn write_launcher(
    out: &mut String,
    module: &ModuleDef,
    kernel: &KernelDef,
) -> Result<(), CodegenError> {
    let place = format!("{}, kernel {}", module.source, kernel.name);
    let name = ident(&kernel.name, &place)?;
    doc_lines(out, "    ", &kernel.doc);
    if !kernel.doc.is_empty() {
        let _ = writeln!(out, "    ///");
    }
    let (dim_type, dim_arg) = if kernel.dim == 1 {
        ("usize".to_owned(), "&[dim]")
    } else {
        (format!("[usize; {}]", kernel.dim), "&dim")
    };
    let _ = writeln!(
        out,
        "    /// `{}` in `{}`, launched over `dim` threads ({} per block) on `stream`.",
        kernel.name, module.source, kernel.block_dim
    );
    let _ = writeln!(
        out,
        "    /// Arrays (`_in` read, `_out` written, `_inout` both): {}.\n    /// Launch contract: {}.",
        array_directions(kernel),
        kernel
            .launch
            .iter()
            .map(|r| format!("`{r}`"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(
        out,
        "    #[allow(clippy::too_many_arguments)]\n    pub fn {name}(\n        &self,\n        stream: &Stream,\n        dim: {dim_type},"
    );
    let mut packing = String::new();
    for (index, p) in kernel.params.iter().enumerate() {
        let arg = ident(&p.launcher_name(), &place)?;
        let _ = writeln!(out, "        {arg}: {},", param_type(p));
        let setter = match p.ty {
            SlotType::Value(_) => format!("set_value({index}, &{arg})"),
            SlotType::Array { .. } => format!("set_array({index}, {arg})"),
            SlotType::Struct(_) => format!("set_struct({index}, {arg})"),
        };
        let _ = writeln!(packing, "        args.{setter}?;");
    }
    let _ = writeln!(
        out,
        "    ) -> Result<(), EnvError> {{\n        let mut args = ArgBuffer::new(&{})?;",
        const_name(&kernel.name)
    );
    out.push_str(&packing);
    let _ = writeln!(
        out,
        "        launch(stream, &self.{name}, args, {dim_arg})\n    }}"
    );
    Ok(())
}

/// The generated source for `manifest` (validated by `EnvManifest::parse`).
pub fn generate(manifest: &EnvManifest) -> Result<String, CodegenError> {
    let mut out = String::from(
        "// @generated by build.rs (build/env_codegen.rs) from ptx/env/manifest.json. Do not edit:\n\
         // change kernels_py/env/, run `python kernels_py/compile.py --only env`, rebuild.\n\n",
    );
    for (name, def) in &manifest.structs {
        write_struct(&mut out, name, &def.fields, def.size)?;
    }
    for (module, kernel) in manifest.kernels() {
        let rules = kernel.launch_rules().map_err(|reason| {
            CodegenError(format!(
                "{}, kernel {}: {reason}",
                module.source, kernel.name
            ))
        })?;
        write_abi(&mut out, module, kernel, &rules);
    }
    let consts: Vec<String> = manifest
        .kernels()
        .map(|(_, k)| format!("&{}", const_name(&k.name)))
        .collect();
    let _ = writeln!(
        out,
        "/// Every env kernel this binary was built with, in manifest order.\npub const KERNELS: &[&KernelAbi] = &[{}];\n",
        consts.join(", ")
    );

    out.push_str(
        "/// The env kernels, loaded: one launch function per kernel of `ptx/env/manifest.json`.\n\
         #[derive(Debug, Clone)]\npub struct EnvKernels {\n",
    );
    for (_, kernel) in manifest.kernels() {
        let _ = writeln!(out, "    {}: Function,", ident(&kernel.name, "kernel")?);
    }
    out.push_str(
        "}\n\nimpl EnvKernels {\n    /// Loads every env module from the PTX embedded in this binary and checks each kernel's\n    /// parameter layout against the driver's (`EnvError::AbiMismatch` if they differ).\n    pub fn load(gpu: &Gpu) -> Result<EnvKernels, EnvError> {\n",
    );
    if manifest.modules.is_empty() {
        out.push_str("        let _ = gpu;\n");
    }
    if !manifest.modules.is_empty() {
        out.push_str("        preload_modules(gpu, &[\n");
        for module in &manifest.modules {
            let _ = writeln!(out, "            {},", str_lit(&module.ptx));
        }
        out.push_str("        ])?;\n");
    }
    for (m, module) in manifest.modules.iter().enumerate() {
        let _ = writeln!(
            out,
            "        let module_{m} = load_module(gpu, {})?;",
            str_lit(&module.ptx)
        );
    }
    out.push_str("        Ok(EnvKernels {\n");
    for (m, module) in manifest.modules.iter().enumerate() {
        for kernel in &module.kernels {
            let _ = writeln!(
                out,
                "            {}: bind_kernel(&module_{m}, &{})?,",
                ident(&kernel.name, "kernel")?,
                const_name(&kernel.name)
            );
        }
    }
    out.push_str("        })\n    }\n\n");
    for (i, (module, kernel)) in manifest.kernels().enumerate() {
        if i > 0 {
            out.push('\n');
        }
        write_launcher(&mut out, module, kernel)?;
    }
    out.push_str("}\n");
    Ok(out)
}
