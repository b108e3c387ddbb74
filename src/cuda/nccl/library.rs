//! Opening libnccl at run time. NCCL ships with neither the driver nor (as a shared library
//! found by default) the CUDA toolkit: pip's `nvidia-nccl-cu12` / `nvidia-nccl-cu13` wheels,
//! PyTorch's bundled copy (`site-packages/nvidia/nccl/lib`) or the distribution's `libnccl2`
//! provide it. It is opened only when a run uses more than one GPU (or a test asks), so a
//! single-GPU run still needs only the driver.
//!
//! cudarc's own loader (`cudarc::nccl::sys::culib`) is never called: it looks for `libnccl.so`
//! and CUDA-versioned names (`libnccl.so.12`, ...), but NCCL's soname is `libnccl.so.2`, the only
//! name the pip wheels and PyTorch ship; and it panics on a missing library or symbol. This
//! module tries the soname first, then cudarc's candidates, and looks every entry point up
//! once, returning an error instead. cudarc's `nccl` bindings still give the types.

use std::ffi::{CStr, c_char, c_int, c_void};
use std::sync::OnceLock;

use cudarc::nccl::sys::{cudaStream_t, ncclComm_t, ncclUniqueId};

use crate::cuda::CudaError;

/// The oldest NCCL this crate accepts (`NCCL_VERSION_CODE`, 10000 x major + 100 x minor +
/// patch): stream capture of collectives came in 2.9, `ncclAvg` in 2.10; 2.18 is the oldest
/// release whose abort and graph-teardown behavior docs/train.md describes.
pub const MIN_NCCL_VERSION: c_int = 21800;

/// A raw `ncclResult_t`: read as an int, since a newer library may return a code cudarc's enum
/// has no variant for (reading it as the enum would be undefined behavior).
pub(super) type RawResult = c_int;

type GetVersion = unsafe extern "C" fn(*mut c_int) -> RawResult;
type GetErrorString = unsafe extern "C" fn(RawResult) -> *const c_char;
type GetLastError = unsafe extern "C" fn(ncclComm_t) -> *const c_char;
type CommInitAll = unsafe extern "C" fn(*mut ncclComm_t, c_int, *const c_int) -> RawResult;
type GetUniqueId = unsafe extern "C" fn(*mut ncclUniqueId) -> RawResult;
type CommInitRank = unsafe extern "C" fn(*mut ncclComm_t, c_int, ncclUniqueId, c_int) -> RawResult;
type CommFree = unsafe extern "C" fn(ncclComm_t) -> RawResult;
type AllReduce = unsafe extern "C" fn(
    *const c_void,
    *mut c_void,
    usize,
    c_int,
    c_int,
    ncclComm_t,
    cudaStream_t,
) -> RawResult;
type Group = unsafe extern "C" fn() -> RawResult;

/// The loaded library and the entry points this crate calls.
pub(super) struct NcclLibrary {
    /// Kept loaded for the life of the process (it lives in a `static`): the function pointers
    /// below point into it.
    _library: libloading::Library,
    /// The file name that loaded, e.g. `libnccl.so.2`.
    pub(super) name: String,
    /// `ncclGetVersion`'s code.
    pub(super) version: c_int,
    pub(super) get_error_string: GetErrorString,
    pub(super) get_last_error: GetLastError,
    pub(super) comm_init_all: CommInitAll,
    pub(super) get_unique_id: GetUniqueId,
    pub(super) comm_init_rank: CommInitRank,
    pub(super) comm_destroy: CommFree,
    pub(super) comm_abort: CommFree,
    pub(super) all_reduce: AllReduce,
    pub(super) group_start: Group,
    pub(super) group_end: Group,
}

/// Where to find NCCL, for the error of a missing or unusable library.
pub const NCCL_HELP: &str = "multi-GPU training (--gpus with more than one device) needs NCCL's libnccl.so.2 on the library path: `pip install nvidia-nccl-cu12` (or -cu13) and put its site-packages/nvidia/nccl/lib on LD_LIBRARY_PATH; PyTorch's bundled copy works too (its environment's site-packages/nvidia/nccl/lib), as does the distribution's libnccl2; one GPU needs no NCCL";

/// The names tried, in order: NCCL's soname, the development symlink, then cudarc's candidates.
fn candidates() -> Vec<String> {
    let mut names = vec!["libnccl.so.2".to_owned(), "libnccl.so".to_owned()];
    for name in cudarc::get_lib_name_candidates("nccl") {
        if !names.contains(&name) {
            names.push(name);
        }
    }
    names
}

/// The library, opened on the first call; later calls return the same result.
pub(super) fn library() -> Result<&'static NcclLibrary, CudaError> {
    static LIBRARY: OnceLock<Result<NcclLibrary, String>> = OnceLock::new();
    LIBRARY
        .get_or_init(open)
        .as_ref()
        .map_err(|reason| CudaError::NcclUnavailable {
            reason: reason.clone(),
        })
}

fn open() -> Result<NcclLibrary, String> {
    let names = candidates();
    let mut opened = None;
    for name in &names {
        // SAFETY: loading runs the library's initializers; libnccl's are NCCL's own and need no
        // state of ours (it initializes itself lazily at the first API call).
        if let Ok(library) = unsafe { libloading::Library::new(name) } {
            opened = Some((name.clone(), library));
            break;
        }
    }
    let (name, library) = opened.ok_or_else(|| {
        format!(
            "no NCCL library found (tried {})",
            names.iter().take(2).cloned().collect::<Vec<_>>().join(", ")
        )
    })?;
    macro_rules! symbol {
        ($ty:ty, $name:literal) => {{
            // SAFETY: the symbol is NCCL's public entry point of that name, whose C signature
            // (nccl.h, NCCL 2.x) is the function type `$ty`; enums are passed as C ints, which
            // is their ABI. The pointer is copied out and used only while `library` stays
            // loaded: both live together in the `static` for the rest of the process.
            let found = unsafe { library.get::<$ty>($name.as_bytes()) };
            *found.map_err(|_| format!("{name} has no {} (NCCL 2.x needed)", $name))?
        }};
    }
    let get_version = symbol!(GetVersion, "ncclGetVersion");
    let mut version: c_int = 0;
    // SAFETY: ncclGetVersion writes one int through a live local.
    let code = unsafe { get_version(&mut version) };
    if code != 0 || version < MIN_NCCL_VERSION {
        return Err(format!(
            "{name} is NCCL {} (code {code}); instantmimic needs NCCL {} or newer",
            describe_version(version),
            describe_version(MIN_NCCL_VERSION)
        ));
    }
    Ok(NcclLibrary {
        get_error_string: symbol!(GetErrorString, "ncclGetErrorString"),
        get_last_error: symbol!(GetLastError, "ncclGetLastError"),
        comm_init_all: symbol!(CommInitAll, "ncclCommInitAll"),
        get_unique_id: symbol!(GetUniqueId, "ncclGetUniqueId"),
        comm_init_rank: symbol!(CommInitRank, "ncclCommInitRank"),
        comm_destroy: symbol!(CommFree, "ncclCommDestroy"),
        comm_abort: symbol!(CommFree, "ncclCommAbort"),
        all_reduce: symbol!(AllReduce, "ncclAllReduce"),
        group_start: symbol!(Group, "ncclGroupStart"),
        group_end: symbol!(Group, "ncclGroupEnd"),
        name,
        version,
        _library: library,
    })
}

/// `2.21.5` for the code 22105.
pub fn describe_version(code: c_int) -> String {
    format!("{}.{}.{}", code / 10000, code % 10000 / 100, code % 100)
}

impl NcclLibrary {
    /// NCCL's name of a result code, e.g. "unhandled cuda error".
    pub(super) fn error_string(&self, code: RawResult) -> String {
        // SAFETY: ncclGetErrorString returns a pointer to a static NUL-terminated string for
        // any code (unknown ones included), or null, checked below.
        let text = unsafe { (self.get_error_string)(code) };
        if text.is_null() {
            return format!("NCCL error {code}");
        }
        // SAFETY: non-null, NUL-terminated and static (NCCL's string table).
        unsafe { CStr::from_ptr(text) }
            .to_string_lossy()
            .into_owned()
    }

    /// NCCL's last error message for `comm` (more detail than the code), if any.
    pub(super) fn last_error(&self, comm: ncclComm_t) -> Option<String> {
        // SAFETY: ncclGetLastError accepts a live communicator or null and returns a pointer to
        // a NUL-terminated string owned by NCCL, valid until the next NCCL call of this thread;
        // it is copied at once.
        let text = unsafe { (self.get_last_error)(comm) };
        if text.is_null() {
            return None;
        }
        // SAFETY: non-null and NUL-terminated, read before any other NCCL call.
        let message = unsafe { CStr::from_ptr(text) }
            .to_string_lossy()
            .trim()
            .to_owned();
        (!message.is_empty()).then_some(message)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_soname_is_tried_first_and_candidates_are_unique() {
        let names = candidates();
        assert_eq!(names[0], "libnccl.so.2");
        assert_eq!(names[1], "libnccl.so");
        let mut sorted = names.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), names.len());
    }

    #[test]
    fn versions_read_as_releases() {
        assert_eq!(describe_version(22105), "2.21.5");
        assert_eq!(describe_version(MIN_NCCL_VERSION), "2.18.0");
    }

    #[test]
    fn the_help_names_pip_pytorch_and_the_library_path() {
        for needle in [
            "nvidia-nccl-cu12",
            "LD_LIBRARY_PATH",
            "site-packages/nvidia/nccl/lib",
            "libnccl.so.2",
        ] {
            assert!(NCCL_HELP.contains(needle), "{needle}");
        }
    }
}
