//! Parsing a raw `.wrp` file into a [`Plan`]: the header and section table here, the sections
//! in the submodules. Every size, offset, count and region id is checked; a malformed file is
//! an error that names the record and byte, never a panic.

mod extended_ops;
mod launch;
mod memory;
mod metadata;
mod ops;

use super::cursor::Cursor;
use super::error::{PlanError, Result};
use super::format::{
    DeviceType, FORMAT_VERSION, HEADER_SIZE, MAGIC, MAX_SECTIONS, SECTION_ENTRY_SIZE,
    SECTION_MEMORY, SECTION_METADATA, SECTION_OPERATIONS, SECTION_PLAN_INFO,
};
use super::model::{Plan, PlanHeader, PlanInfo};
use super::validate::PlanIndex;

/// Deepest IF/WHILE nesting the reader accepts. MuJoCo Warp nests one level; the limit keeps
/// the recursive reader (and the recursive writer, comparisons and drops of the op tree) far
/// from the stack's end on a malformed file, even in a debug build on a 2 MiB thread.
pub const MAX_NESTING_DEPTH: usize = 32;

impl Plan {
    /// Parses and validates a raw `.wrp` file (see [`super::load_plan`] for packed files too).
    pub fn parse(bytes: &[u8]) -> Result<Plan> {
        let header = read_header(bytes)?;
        let sections = read_section_table(bytes, &header)?;

        let metadata = metadata::read(sections.metadata, &header.plan)?;
        let regions = memory::read(sections.memory)?;
        let index = PlanIndex::new(&regions, &metadata.kernels);
        metadata::check_references(&metadata, &index)?;
        let ops = ops::read_section(sections.operations, &index)?;
        let info = match sections.info {
            Some(info) => Some(read_info(info)?),
            None => None,
        };

        Ok(Plan {
            header: header.plan,
            producer: metadata.producer,
            modules: metadata.modules,
            kernels: metadata.kernels,
            bindings: metadata.bindings,
            meshes: metadata.meshes,
            handle_locations: metadata.handle_locations,
            regions,
            ops,
            info,
        })
    }
}

struct FileHeader {
    plan: PlanHeader,
    num_sections: u32,
    section_table_offset: u64,
}

fn read_header(bytes: &[u8]) -> Result<FileHeader> {
    let start = bytes.get(..MAGIC.len()).unwrap_or(bytes);
    if MAGIC.get(..start.len()) != Some(start) {
        return Err(PlanError::BadMagic {
            found: start.to_vec(),
        });
    }
    let mut c = Cursor::new(bytes, 0, "the file");
    c.set_context("the file header: ");
    c.take(MAGIC.len() as u64, "magic")?;
    let version = c.u32("version")?;
    if version != FORMAT_VERSION {
        return Err(PlanError::UnsupportedVersion {
            place: "file header",
            found: version,
            supported: FORMAT_VERSION,
        });
    }
    c.reserved::<4>("flags")?;
    let num_sections = c.u32("section count")?;
    let section_table_offset = c.u64("section table offset")?;
    let device_code = c.u8("device type")?;
    c.reserved::<3>("device type padding")?;
    let target_arch = c.u32("target architecture")?;
    c.reserved::<32>("reserved words")?;

    let device = DeviceType::from_code(device_code).ok_or_else(|| {
        PlanError::malformed(
            "the file header",
            format!("unknown device type {device_code} (0 is CUDA, 1 is CPU)"),
        )
    })?;
    let arch_ok = match device {
        DeviceType::Cuda => target_arch > 0 && target_arch <= i32::MAX as u32,
        DeviceType::Cpu => target_arch == 0,
    };
    if !arch_ok {
        return Err(PlanError::malformed(
            "the file header",
            format!(
                "device type {device} does not fit target architecture {target_arch} (CUDA needs an SM version, CPU needs 0)"
            ),
        ));
    }
    Ok(FileHeader {
        plan: PlanHeader {
            version,
            device,
            target_arch,
        },
        num_sections,
        section_table_offset,
    })
}

/// The sections' bytes, each as a cursor that reports absolute file offsets.
struct Sections<'a> {
    metadata: Cursor<'a>,
    memory: Cursor<'a>,
    operations: Cursor<'a>,
    info: Option<Cursor<'a>>,
}

fn section_name(kind: u32) -> &'static str {
    match kind {
        SECTION_METADATA => "metadata",
        SECTION_MEMORY => "memory",
        SECTION_OPERATIONS => "operations",
        SECTION_PLAN_INFO => "plan info",
        _ => "unknown",
    }
}

fn section_container(kind: u32) -> &'static str {
    match kind {
        SECTION_METADATA => "the metadata section",
        SECTION_MEMORY => "the memory section",
        SECTION_OPERATIONS => "the operations section",
        _ => "the plan info section",
    }
}

/// `len` bytes at `offset` of the file, or a truncation error naming `what`.
fn file_range<'a>(
    bytes: &'a [u8],
    offset: u64,
    len: u64,
    what: &str,
    container: &'static str,
) -> Result<Cursor<'a>> {
    let mut file = Cursor::new(bytes, 0, "the file");
    let skip = offset.min(bytes.len() as u64);
    file.take(skip, "")?;
    if skip < offset {
        return Err(PlanError::Truncated {
            what: what.to_string(),
            offset,
            needed: len,
            container: "the file",
            end: bytes.len() as u64,
        });
    }
    file.sub(len, what, container)
}

fn read_section_table<'a>(bytes: &'a [u8], header: &FileHeader) -> Result<Sections<'a>> {
    let count = header.num_sections;
    if count == 0 || count > MAX_SECTIONS {
        return Err(PlanError::malformed(
            "the file header",
            format!("section count {count} is outside 1..={MAX_SECTIONS}"),
        ));
    }
    let table_offset = header.section_table_offset;
    let table_len = u64::from(count) * SECTION_ENTRY_SIZE as u64;
    if table_offset < HEADER_SIZE as u64 {
        return Err(PlanError::malformed(
            "the file header",
            format!(
                "the section table at offset {table_offset} overlaps the {HEADER_SIZE}-byte header"
            ),
        ));
    }
    let mut table = file_range(
        bytes,
        table_offset,
        table_len,
        "the section table",
        "the file",
    )?;

    // Byte ranges that must not overlap: the header, the table and every section.
    let mut used: Vec<(u64, u64, String)> = vec![
        (0, HEADER_SIZE as u64, "the file header".to_string()),
        (
            table_offset,
            table_offset + table_len,
            "the section table".to_string(),
        ),
    ];
    let mut found: [Option<Cursor<'a>>; 4] = [None, None, None, None];
    for i in 0..count {
        table.set_context(format!("section table entry {i}: "));
        let kind = table.u32("type")?;
        table.reserved::<4>("flags")?;
        let offset = table.u64("offset")?;
        let size = table.u64("size")?;
        let uncompressed = table.u64("uncompressed size")?;
        let at = format!("section table entry {i} ({} section)", section_name(kind));
        let slot = match kind {
            SECTION_METADATA => 0,
            SECTION_MEMORY => 1,
            SECTION_OPERATIONS => 2,
            SECTION_PLAN_INFO => 3,
            other => {
                return Err(PlanError::malformed(
                    at,
                    format!(
                        "unknown section type {other:#x} (known: 0x1 metadata, 0x2 memory, 0x3 operations, 0x100 plan info)"
                    ),
                ));
            }
        };
        if uncompressed != size {
            return Err(PlanError::malformed(
                at,
                format!(
                    "compressed sections are not supported (size {size}, uncompressed size {uncompressed})"
                ),
            ));
        }
        let what = format!("the {} section", section_name(kind));
        let cursor = file_range(bytes, offset, size, &what, section_container(kind))?;
        if found.get(slot).is_some_and(Option::is_some) {
            return Err(PlanError::malformed(
                at,
                format!("duplicate {} section", section_name(kind)),
            ));
        }
        if size > 0 {
            used.push((offset, offset + size, what));
        }
        if let Some(entry) = found.get_mut(slot) {
            *entry = Some(cursor);
        }
    }

    used.sort_by_key(|&(start, end, _)| (start, end));
    for pair in used.windows(2) {
        if let [(a_start, a_end, a), (b_start, b_end, b)] = pair
            && b_start < a_end
        {
            return Err(PlanError::malformed(
                "the section table",
                format!("{b} [{b_start}, {b_end}) overlaps {a} [{a_start}, {a_end})"),
            ));
        }
    }

    let [metadata, memory, operations, info] = found;
    let required = |cursor: Option<Cursor<'a>>, kind: u32| {
        cursor.filter(|c| !c.is_empty()).ok_or_else(|| {
            PlanError::malformed(
                "the section table",
                format!(
                    "the required {} section is missing or empty",
                    section_name(kind)
                ),
            )
        })
    };
    Ok(Sections {
        metadata: required(metadata, SECTION_METADATA)?,
        memory: required(memory, SECTION_MEMORY)?,
        operations: required(operations, SECTION_OPERATIONS)?,
        info,
    })
}

fn read_info(mut section: Cursor<'_>) -> Result<PlanInfo> {
    let len = section.remaining() as u64;
    let json = section.take(len, "plan info")?;
    serde_json::from_slice(json).map_err(|source| PlanError::InfoJson { source })
}
