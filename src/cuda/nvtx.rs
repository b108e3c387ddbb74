//! NVTX ranges for Nsight Systems timelines. A no-op when libnvToolsExt is not installed.

use std::ffi::CString;
use std::sync::OnceLock;

use cudarc::nvtx::sys;

fn nvtx_available() -> bool {
    static AVAILABLE: OnceLock<bool> = OnceLock::new();
    // SAFETY: only tries to dlopen libnvToolsExt and drops the handle.
    *AVAILABLE.get_or_init(|| unsafe { sys::is_culib_present() })
}

/// A pushed NVTX range, popped on drop.
#[must_use = "the range ends when this value is dropped"]
#[derive(Debug)]
pub struct NvtxRange {
    pushed: bool,
}

impl NvtxRange {
    /// Pushes a range named `name` (NUL bytes in it are dropped).
    pub fn push(name: &str) -> NvtxRange {
        if !nvtx_available() {
            return NvtxRange { pushed: false };
        }
        let name = CString::new(name.replace('\0', "")).unwrap_or_default();
        // SAFETY: the library is present; `name` is a NUL-terminated string alive for the call
        // (NVTX copies it).
        let depth = unsafe { sys::nvtxRangePushA(name.as_ptr()) };
        NvtxRange { pushed: depth >= 0 }
    }
}

impl Drop for NvtxRange {
    fn drop(&mut self) {
        if self.pushed {
            // SAFETY: pairs with the successful push of this value on the library loaded above.
            unsafe { sys::nvtxRangePop() };
        }
    }
}
