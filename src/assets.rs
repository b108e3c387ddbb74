//! Files from `ptx/` embedded in the binary by `build.rs`, so a run needs no files beside the
//! binary: the PTX of every module and the committed physics plans.

include!(concat!(env!("OUT_DIR"), "/embedded_assets.rs"));

/// An embedded file by its path relative to `ptx/` (e.g. `plans/manifest.json`).
pub fn get(path: &str) -> Option<&'static [u8]> {
    ASSETS
        .iter()
        .find(|(p, _)| *p == path)
        .map(|(_, bytes)| *bytes)
}

/// Every embedded file whose path starts with `prefix`.
pub fn list(prefix: &str) -> impl Iterator<Item = (&'static str, &'static [u8])> + '_ {
    ASSETS
        .iter()
        .copied()
        .filter(move |(p, _)| p.starts_with(prefix))
}
