//! A CLI agent as the backend: the configured `argv` runs directly (no shell, so nothing in
//! the prompt or the configuration is interpolated), the prompt goes to its stdin, its stdout
//! is the reply. A non-zero exit or a run past the timeout is a failed request, retried as
//! configured.

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::hpo::backend::{AgentRequest, Backend, BackendError, tail};

/// `[agent.command]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandSettings {
    /// The program and its arguments, e.g. `["codex", "exec", "-"]`.
    pub argv: Vec<String>,
    /// Seconds one run may take.
    #[serde(default = "defaults::timeout_s")]
    pub timeout_s: f64,
    /// Retries after the first try.
    #[serde(default = "defaults::retries")]
    pub retries: u32,
    /// Working directory of the agent (default: the current one).
    pub cwd: Option<PathBuf>,
}

mod defaults {
    pub fn timeout_s() -> f64 {
        1800.0
    }
    pub fn retries() -> u32 {
        1
    }
}

impl CommandSettings {
    pub(crate) fn check(&self) -> Result<(), String> {
        if self.argv.first().is_none_or(|p| p.trim().is_empty()) {
            return Err(
                "[agent.command] argv must name a program, e.g. [\"codex\", \"exec\", \"-\"]"
                    .to_string(),
            );
        }
        if !(self.timeout_s.is_finite() && self.timeout_s > 0.0) {
            return Err(
                "[agent.command] timeout_s must be a positive number of seconds".to_string(),
            );
        }
        Ok(())
    }
}

/// Output beyond this is dropped (a reply is a few kilobytes).
const MAX_OUTPUT_BYTES: usize = 8 * 1024 * 1024;

/// The command backend.
pub struct CommandBackend {
    settings: CommandSettings,
}

impl CommandBackend {
    pub fn new(settings: CommandSettings) -> Self {
        CommandBackend { settings }
    }

    fn program(&self) -> String {
        self.settings.argv.first().cloned().unwrap_or_default()
    }

    /// One run.
    fn run_once(&self, prompt: &str) -> Result<String, BackendError> {
        let program = self.program();
        let mut command = Command::new(&program);
        command
            .args(self.settings.argv.iter().skip(1))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        if let Some(cwd) = &self.settings.cwd {
            command.current_dir(cwd);
        }
        let mut child = command.spawn().map_err(|e| BackendError::Spawn {
            program: program.clone(),
            problem: e.to_string(),
        })?;
        // Feed stdin and drain stdout/stderr on their own threads: a child that fills a pipe
        // while we wait on another would otherwise deadlock.
        if let Some(mut stdin) = child.stdin.take() {
            let prompt = prompt.to_string();
            std::thread::spawn(move || {
                // A child that exits without reading its stdin closes the pipe: not our error.
                let _ = stdin.write_all(prompt.as_bytes());
            });
        }
        let (sender, outputs) = mpsc::channel();
        for (which, pipe) in [
            (
                0,
                child
                    .stdout
                    .take()
                    .map(|p| Box::new(p) as Box<dyn Read + Send>),
            ),
            (
                1,
                child
                    .stderr
                    .take()
                    .map(|p| Box::new(p) as Box<dyn Read + Send>),
            ),
        ] {
            if let Some(pipe) = pipe {
                let sender = sender.clone();
                std::thread::spawn(move || {
                    let _ = sender.send((which, read_capped(pipe)));
                });
            }
        }
        drop(sender);
        let timeout = Duration::from_secs_f64(self.settings.timeout_s);
        let started = Instant::now();
        let status = wait_until(&mut child, started + timeout).map_err(|problem| {
            BackendError::CommandIo {
                program: program.clone(),
                problem,
            }
        })?;
        let Some(status) = status else {
            return Err(BackendError::CommandTimeout {
                program,
                seconds: self.settings.timeout_s,
            });
        };
        // The pipes close when the child exits (unless it left a child of its own holding
        // them): wait for the readers a little, not forever.
        let mut stdout = Vec::new();
        let mut stderr = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(5);
        while let Ok((which, bytes)) =
            outputs.recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            if which == 0 {
                stdout = bytes;
            } else {
                stderr = bytes;
            }
        }
        if !status.success() {
            return Err(BackendError::Exit {
                program,
                status: status.to_string(),
                stderr: tail(&String::from_utf8_lossy(&stderr), 500),
            });
        }
        Ok(String::from_utf8_lossy(&stdout).into_owned())
    }
}

/// Waits for the child until `deadline`; kills it and returns `None` past it.
fn wait_until(
    child: &mut Child,
    deadline: Instant,
) -> Result<Option<std::process::ExitStatus>, String> {
    loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            return Ok(Some(status));
        }
        if Instant::now() >= deadline {
            // The child may have exited just now: both errors mean it is gone.
            let _ = child.kill();
            let _ = child.wait();
            return Ok(None);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Reads a pipe to its end, keeping at most `MAX_OUTPUT_BYTES`.
fn read_capped(mut pipe: Box<dyn Read + Send>) -> Vec<u8> {
    let mut kept = Vec::new();
    let mut chunk = [0u8; 8192];
    loop {
        match pipe.read(&mut chunk) {
            Ok(0) | Err(_) => return kept,
            Ok(n) => {
                let room = MAX_OUTPUT_BYTES.saturating_sub(kept.len());
                kept.extend_from_slice(chunk.get(..n.min(room)).unwrap_or_default());
            }
        }
    }
}

impl Backend for CommandBackend {
    fn reply(&mut self, request: &AgentRequest<'_>) -> Result<String, BackendError> {
        let mut attempt = 0;
        loop {
            match self.run_once(request.prompt) {
                Ok(reply) => return Ok(reply),
                Err(error) if !error.is_fatal() && attempt < self.settings.retries => attempt += 1,
                Err(error) => return Err(error),
            }
        }
    }
}
