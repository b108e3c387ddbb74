//! The `.param` declarations NVRTC writes into a kernel's PTX, read back so that
//! [`super::manifest::KernelDef::check_ptx`] can compare them with the manifest. Like the
//! manifest, `build.rs` includes this file (`#[path]`): std only.

/// `(size, align)` of each parameter of `.entry <entry>( ... )` in PTX text:
/// `.param .align 8 .b8 name[56]` is (56, 8), `.param .f32 name` is (4, 4).
pub fn ptx_entry_params(ptx: &str, entry: &str) -> Result<Vec<(usize, usize)>, String> {
    let start = ptx
        .match_indices(".entry")
        .find_map(|(at, _)| {
            let rest = ptx[at + ".entry".len()..].trim_start();
            let rest = rest.strip_prefix(entry)?;
            rest.trim_start().strip_prefix('(')
        })
        .ok_or_else(|| format!("no `.entry {entry}(` in the PTX"))?;
    let list = start
        .split_once(')')
        .map(|(list, _)| list)
        .ok_or_else(|| format!("the parameter list of {entry} does not end"))?;
    let mut params = Vec::new();
    for decl in list.split(',').map(str::trim).filter(|d| !d.is_empty()) {
        params.push(
            parse_param(decl).ok_or_else(|| {
                format!("cannot read the parameter declaration {decl:?} of {entry}")
            })?,
        );
    }
    Ok(params)
}

fn parse_param(decl: &str) -> Option<(usize, usize)> {
    let mut words = decl.split_whitespace();
    if words.next()? != ".param" {
        return None;
    }
    let mut word = words.next()?;
    let mut align = None;
    if word == ".align" {
        align = Some(words.next()?.parse::<usize>().ok()?);
        word = words.next()?;
    }
    // .b8 .u32 .f64 .s16 .pred: the bit width follows the type letter(s).
    let bits: String = word.chars().filter(char::is_ascii_digit).collect();
    let element = bits.parse::<usize>().ok()?.div_ceil(8);
    let name = words.next()?;
    if words.next().is_some() {
        return None;
    }
    let count = match name.split_once('[') {
        Some((_, count)) => count.strip_suffix(']')?.parse::<usize>().ok()?,
        None => 1,
    };
    Some((element * count, align.unwrap_or(element)))
}
