//! PTX text handling before the driver sees it: pure functions, tested without a GPU.
//!
//! Warp's NVRTC writes the PTX ISA version of its own toolkit (`.version 9.4` for CUDA 13.4),
//! while the driver's JIT refuses any version newer than its own CUDA release
//! (`CUDA_ERROR_UNSUPPORTED_PTX_VERSION`). Warp's kernels use no instruction newer than the
//! versions drivers accept, so lowering the directive to the driver's maximum loads and runs
//! (measured: PTX 9.4 rewritten to 8.0 ran on driver 580). CI assembles every shipped module at
//! the lowest version it supports with ptxas, which catches a kernel that does need a newer ISA.

use std::fmt;
use std::str::FromStr;

use super::CudaError;

/// A PTX ISA version, as written in the `.version` directive.
///
/// Ordered by `(major, minor)`, so `PtxIsa::new(8, 7) < PtxIsa::new(9, 0)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct PtxIsa {
    pub major: u32,
    pub minor: u32,
}

impl PtxIsa {
    pub const fn new(major: u32, minor: u32) -> Self {
        Self { major, minor }
    }

    /// The highest PTX ISA the JIT of a driver accepts, from `cuDriverGetVersion`
    /// (`1000 * major + 10 * minor`: 13000 is CUDA 13.0).
    ///
    /// NVIDIA's PTX ISA release history (PTX ISA manual, "Release Notes"), one PTX ISA per CUDA
    /// release:
    ///
    /// | CUDA       | PTX ISA    |
    /// |------------|------------|
    /// | 11.0..11.8 | 7.0..7.8   |
    /// | 12.0..12.5 | 8.0..8.5   |
    /// | 12.6       | 8.5 (no new ISA) |
    /// | 12.7       | 8.6        |
    /// | 12.8       | 8.7        |
    /// | 12.9       | 8.8        |
    /// | 13.x       | 9.x (13.0 is 9.0, 13.4 is 9.4) |
    ///
    /// A driver accepts every ISA up to its own, so later minor releases of a known major keep
    /// its last known ISA, and majors after 13 are extrapolated as `major - 4` (the rule since
    /// CUDA 11). Drivers before CUDA 11 map to 6.3 (CUDA 10.0); this crate refuses them anyway.
    pub fn for_driver(driver_version: i32) -> PtxIsa {
        let major = driver_version.max(0) / 1000;
        let minor = ((driver_version.max(0) % 1000) / 10) as u32;
        match major {
            ..=10 => PtxIsa::new(6, 3),
            11 => PtxIsa::new(7, minor.min(8)),
            12 => match minor {
                0..=5 => PtxIsa::new(8, minor),
                6 => PtxIsa::new(8, 5),
                7 => PtxIsa::new(8, 6),
                8 => PtxIsa::new(8, 7),
                _ => PtxIsa::new(8, 8),
            },
            major => PtxIsa::new(major as u32 - 4, minor),
        }
    }
}

impl fmt::Display for PtxIsa {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}", self.major, self.minor)
    }
}

impl FromStr for PtxIsa {
    type Err = CudaError;

    /// Parses `"9.4"`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || CudaError::PtxText(format!("{s:?} is not a PTX ISA version like 8.7"));
        let (major, minor) = s.trim().split_once('.').ok_or_else(bad)?;
        let digits = |t: &str| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit());
        if !digits(major) || !digits(minor) {
            return Err(bad());
        }
        Ok(PtxIsa::new(
            major.parse().map_err(|_| bad())?,
            minor.parse().map_err(|_| bad())?,
        ))
    }
}

/// Where the `.version` directive's number sits in the text, and its value.
struct VersionDirective {
    isa: PtxIsa,
    /// Byte range of `X.Y` in the source.
    start: usize,
    end: usize,
}

/// Finds the first `.version X.Y` line (leading whitespace allowed; `//` comment lines skipped).
fn find_version(src: &str) -> Result<VersionDirective, CudaError> {
    let mut line_start = 0;
    for line in src.split_inclusive('\n') {
        let indent = line.len() - line.trim_start().len();
        let rest = &line[indent..];
        if let Some(after) = rest.strip_prefix(".version")
            && after.starts_with([' ', '\t'])
        {
            let spaces = after.len() - after.trim_start_matches([' ', '\t']).len();
            let number_start = line_start + indent + ".version".len() + spaces;
            let number: &str = &src[number_start..];
            let len = number.find(char::is_whitespace).unwrap_or(number.len());
            let text = &number[..len];
            let isa = text.parse::<PtxIsa>().map_err(|_| {
                CudaError::PtxText(format!(
                    "the .version directive has {text:?} where a version like 8.7 belongs"
                ))
            })?;
            return Ok(VersionDirective {
                isa,
                start: number_start,
                end: number_start + len,
            });
        }
        line_start += line.len();
    }
    Err(CudaError::PtxText(
        "no .version directive found (is this PTX text?)".to_owned(),
    ))
}

/// The PTX ISA version a PTX text declares.
pub fn ptx_version(src: &str) -> Result<PtxIsa, CudaError> {
    find_version(src).map(|d| d.isa)
}

/// Rewrites the `.version` directive to `to` when it declares a newer ISA; everything else
/// stays byte-identical. A text already at or below `to` comes back unchanged.
pub fn lower_ptx_version(src: &str, to: PtxIsa) -> Result<String, CudaError> {
    let directive = find_version(src)?;
    if directive.isa <= to {
        return Ok(src.to_owned());
    }
    let mut out = String::with_capacity(src.len() + 4);
    out.push_str(&src[..directive.start]);
    out.push_str(&to.to_string());
    out.push_str(&src[directive.end..]);
    Ok(out)
}

/// Makes PTX bytes loadable by a driver whose JIT accepts up to `max`: strips trailing NUL
/// bytes (Warp's files end with one), checks UTF-8 and that no NUL is left inside (the driver
/// reads a C string), and lowers `.version` to `max` when higher.
pub fn prepare_ptx(src: &[u8], max: PtxIsa) -> Result<String, CudaError> {
    let end = src.iter().rposition(|&b| b != 0).map_or(0, |i| i + 1);
    let trimmed = &src[..end];
    if let Some(at) = trimmed.iter().position(|&b| b == 0) {
        return Err(CudaError::PtxText(format!(
            "NUL byte at offset {at} inside the text"
        )));
    }
    let text = std::str::from_utf8(trimmed).map_err(|e| {
        CudaError::PtxText(format!(
            "not UTF-8 text (invalid byte at offset {})",
            e.valid_up_to()
        ))
    })?;
    lower_ptx_version(text, max)
}

/// Names of the kernel entry points (`.entry NAME`) a PTX text defines, in order.
pub fn ptx_entry_names(src: &str) -> Vec<&str> {
    let mut names = Vec::new();
    let mut rest = src;
    while let Some(at) = rest.find(".entry") {
        let after = &rest[at + ".entry".len()..];
        let is_directive = at == 0 || rest[..at].ends_with([' ', '\t', '\n']);
        let name_part = after.trim_start_matches([' ', '\t']);
        if is_directive && name_part.len() < after.len() {
            let len = name_part
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '$'))
                .unwrap_or(name_part.len());
            if len > 0 {
                names.push(&name_part[..len]);
            }
        }
        rest = after;
    }
    names
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_with_tabs_and_comments() {
        let src = "//\n// .version 1.0 in a comment\n//\n\t.version\t9.4\n.target sm_90\n";
        assert_eq!(ptx_version(src).unwrap(), PtxIsa::new(9, 4));
    }

    #[test]
    fn versionless_directive_prefix_is_not_a_version() {
        assert!(ptx_version(".versionx 9.4\n").is_err());
    }
}
