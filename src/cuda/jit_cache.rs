//! Compiling PTX in helper processes, so that a first run on a machine does not wait for the
//! driver's JIT one module after another.
//!
//! The driver compiles each PTX module when it is loaded and keeps the result in its JIT cache
//! (`~/.nv/ComputeCache`, or `CUDA_CACHE_PATH`); later loads of the same text read the cache.
//! Within one process the JIT runs one module at a time: loading the modules on 16 threads of one
//! process gained nothing (BENCHMARKS.md, "Setup on a fresh machine"), while separate processes
//! compile at full speed side by side. So, when the largest module of a set takes longer than a
//! cache read to load ([`COLD_LOAD`]), [`Gpu::preload_ptx`] hands the rest of the set to helper
//! processes (this executable run with [`HELPER_COMMAND`]), which fill the cache; the loads that
//! follow here read it. Helpers are best effort: one that fails leaves its modules to the
//! ordinary load, which reports any error with the JIT's log.
//!
//! Only an executable that answers [`HELPER_COMMAND`] (the `instantmimic` binary, which calls
//! [`enable_helpers`]) starts helpers; elsewhere (tests, a library user) modules load in
//! process, as before.

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::module::load_module;
use super::{CudaError, Gpu};

/// The hidden subcommand a helper process runs: `instantmimic __compile-ptx --device N`, the
/// modules on its standard input ([`write_modules`]).
pub const HELPER_COMMAND: &str = "__compile-ptx";

/// A load slower than this compiled the module (a cache read of the largest one takes
/// milliseconds; its JIT, seconds).
pub const COLD_LOAD: Duration = Duration::from_millis(300);

/// How long a helper may take: a set compiles in well under a minute on the machines measured.
const HELPER_TIMEOUT: Duration = Duration::from_secs(180);

/// The most helper processes one set of modules is spread over.
const MAX_HELPERS: usize = 15;

/// What starts helpers: the executable, and what to call once, when the first helpers start (the
/// command line tells the user why setup takes longer this time).
struct Helpers {
    exe: PathBuf,
    on_first_start: Box<dyn Fn(usize) + Send + Sync>,
}

static HELPERS: OnceLock<Helpers> = OnceLock::new();
static STARTED_ONCE: AtomicBool = AtomicBool::new(false);

/// Lets [`Gpu::preload_ptx`] start helper processes of `exe`, which must run [`run_helper`] when
/// called with [`HELPER_COMMAND`]. `on_first_start` is called with the number of helpers when
/// the first of them start, once per process.
pub fn enable_helpers(exe: PathBuf, on_first_start: impl Fn(usize) + Send + Sync + 'static) {
    let _ = HELPERS.set(Helpers {
        exe,
        on_first_start: Box::new(on_first_start),
    });
}

/// Writes `modules` as a helper reads them: for each, the name's length (u32 LE), the name, the
/// PTX's length (u64 LE) and the PTX.
pub fn write_modules(out: &mut impl Write, modules: &[(&str, &[u8])]) -> std::io::Result<()> {
    for (name, ptx) in modules {
        out.write_all(&(name.len() as u32).to_le_bytes())?;
        out.write_all(name.as_bytes())?;
        out.write_all(&(ptx.len() as u64).to_le_bytes())?;
        out.write_all(ptx)?;
    }
    Ok(())
}

/// Reads what [`write_modules`] wrote, to the end of `input`.
pub fn read_modules(input: &mut impl Read) -> std::io::Result<Vec<(String, Vec<u8>)>> {
    let mut modules = Vec::new();
    loop {
        // The end of the input between modules is the end; inside one, an error.
        let mut len = [0u8; 4];
        let first = loop {
            match input.read(&mut len[..1]) {
                Ok(n) => break n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        };
        if first == 0 {
            return Ok(modules);
        }
        input.read_exact(&mut len[1..])?;
        let mut name = vec![0u8; u32::from_le_bytes(len) as usize];
        input.read_exact(&mut name)?;
        let name = String::from_utf8(name).map_err(|_| {
            std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "a module name is not UTF-8",
            )
        })?;
        let mut len = [0u8; 8];
        input.read_exact(&mut len)?;
        let len = usize::try_from(u64::from_le_bytes(len)).map_err(|_| {
            std::io::Error::new(std::io::ErrorKind::InvalidData, "a module length overflows")
        })?;
        let mut ptx = Vec::new();
        input.take(len as u64).read_to_end(&mut ptx)?;
        if ptx.len() != len {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        modules.push((name, ptx));
    }
}

/// `modules` (indices) spread over `bins` sets of about equal PTX size, largest first.
pub fn spread_by_size(sizes: &[usize], bins: usize) -> Vec<Vec<usize>> {
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(sizes[i]));
    let mut sets = vec![(0usize, Vec::new()); bins.max(1)];
    for i in order {
        // The lightest set so far takes the next largest module.
        if let Some(set) = sets.iter_mut().min_by_key(|(total, _)| *total) {
            set.0 += sizes[i];
            set.1.push(i);
        }
    }
    sets.into_iter()
        .map(|(_, set)| set)
        .filter(|set| !set.is_empty())
        .collect()
}

/// A helper process's work: loads every module on its standard input on CUDA device `device`,
/// which leaves each compiled in the driver's cache. The first failure ends it with an error.
pub fn run_helper(device: usize) -> Result<(), CudaError> {
    let gpu = Gpu::open(device)?;
    let modules =
        read_modules(&mut std::io::stdin().lock()).map_err(|e| CudaError::InvalidArgument {
            operation: "reading the modules to compile",
            reason: e.to_string(),
        })?;
    for (name, ptx) in &modules {
        load_module(&gpu.shared.ctx, gpu.info().max_ptx_isa, name, ptx)?;
    }
    Ok(())
}

impl Gpu {
    /// Readies `modules` for [`Gpu::load_ptx`]: when loading the largest of them shows an empty
    /// JIT cache ([`COLD_LOAD`]) and this executable can start helpers ([`enable_helpers`]),
    /// the others are compiled at once by helper processes and this one, so that their loads
    /// read the cache. Otherwise it loads only the largest, and the rest load when asked for.
    pub fn preload_ptx(&self, modules: &[(&str, &[u8])]) -> Result<(), CudaError> {
        let Some((largest, rest)) = split_largest(modules) else {
            return Ok(());
        };
        let started = Instant::now();
        self.load_ptx(largest.0, largest.1)?;
        let Some(helpers) = HELPERS.get() else {
            return Ok(());
        };
        if started.elapsed() < COLD_LOAD
            || rest.is_empty()
            || std::env::var_os("CUDA_CACHE_DISABLE").is_some_and(|v| v == "1")
        {
            return Ok(());
        }
        let processes = std::thread::available_parallelism()
            .map_or(1, std::num::NonZero::get)
            .clamp(1, MAX_HELPERS + 1);
        let sizes: Vec<usize> = rest.iter().map(|(_, ptx)| ptx.len()).collect();
        let mut sets = spread_by_size(&sizes, processes.min(rest.len()));
        // This process compiles one set itself while the helpers compile the others.
        let own = sets.pop().unwrap_or_default();
        if !sets.is_empty() && !STARTED_ONCE.swap(true, Ordering::Relaxed) {
            (helpers.on_first_start)(sets.len());
        }
        let running: Vec<_> = sets
            .iter()
            .filter_map(|set| {
                let chosen: Vec<(&str, &[u8])> = set.iter().map(|&i| rest[i]).collect();
                start_helper(&helpers.exe, self.info().ordinal, &chosen, HELPER_TIMEOUT)
            })
            .collect();
        for &i in &own {
            self.load_ptx(rest[i].0, rest[i].1)?;
        }
        for helper in running {
            // Best effort: a helper that failed leaves its modules to the ordinary load.
            let _ = helper.join();
        }
        Ok(())
    }
}

/// A module's name and PTX.
type NamedPtx<'a> = (&'a str, &'a [u8]);

/// The largest module of `modules` and the others.
fn split_largest<'a>(modules: &[NamedPtx<'a>]) -> Option<(NamedPtx<'a>, Vec<NamedPtx<'a>>)> {
    let index = (0..modules.len()).max_by_key(|&i| modules[i].1.len())?;
    let rest = modules
        .iter()
        .enumerate()
        .filter(|&(i, _)| i != index)
        .map(|(_, m)| *m)
        .collect();
    Some((modules[index], rest))
}

/// A helper process compiling `modules` on device `ordinal`, fed from a thread of its own (its
/// standard input may hold more than a pipe buffers) and killed if it has not ended within
/// `timeout` (a helper stuck in the driver must not hold the run); None when it could not be
/// started. The handle's value: whether the helper took every module and succeeded.
fn start_helper(
    exe: &std::path::Path,
    ordinal: usize,
    modules: &[(&str, &[u8])],
    timeout: Duration,
) -> Option<std::thread::JoinHandle<bool>> {
    let mut bytes = Vec::new();
    write_modules(&mut bytes, modules).ok()?;
    let mut child = Command::new(exe)
        .args([HELPER_COMMAND, "--device", &ordinal.to_string()])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .ok()?;
    let mut stdin = child.stdin.take()?;
    Some(std::thread::spawn(move || {
        let writer = std::thread::spawn(move || stdin.write_all(&bytes).is_ok());
        let deadline = Instant::now() + timeout;
        loop {
            match child.try_wait() {
                Ok(Some(status)) => return writer.join().unwrap_or(false) && status.success(),
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(20));
                }
                _ => {
                    let _ = child.kill();
                    let _ = child.wait();
                    // The writer ends when the pipe closes; nothing waits for it.
                    return false;
                }
            }
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An executable script of `body` in `dir`.
    fn script(dir: &std::path::Path, body: &str) -> PathBuf {
        use std::os::unix::fs::PermissionsExt;
        let path = dir.join("helper.sh");
        std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        path
    }

    #[test]
    fn a_helper_that_hangs_is_killed_at_its_timeout() {
        let dir = tempfile::tempdir().unwrap();
        let exe = script(dir.path(), "sleep 30");
        let big = vec![b'x'; 1 << 20];
        let started = Instant::now();
        let helper = start_helper(&exe, 0, &[("big", &big)], Duration::from_millis(300)).unwrap();
        assert!(!helper.join().unwrap());
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "{:?}",
            started.elapsed()
        );
    }

    #[test]
    fn a_helper_that_reads_everything_and_succeeds_counts_as_done() {
        let dir = tempfile::tempdir().unwrap();
        let exe = script(dir.path(), "cat > /dev/null");
        let big = vec![b'x'; 1 << 20];
        let helper = start_helper(&exe, 0, &[("big", &big)], Duration::from_secs(30)).unwrap();
        assert!(helper.join().unwrap());
        let exe = script(dir.path(), "cat > /dev/null; exit 3");
        let helper = start_helper(&exe, 0, &[("big", &big)], Duration::from_secs(30)).unwrap();
        assert!(!helper.join().unwrap());
    }
}
