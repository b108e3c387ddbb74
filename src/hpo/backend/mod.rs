//! Who answers the plan and propose prompts:
//! - [`chat`]: an OpenAI-compatible chat-completions service;
//! - [`command`]: a CLI agent (`codex exec`, `opencode run`, ...) with the prompt on stdin;
//! - [`offline`]: the built-in coordinate line search, no LLM (the fixed-space baseline).
//!
//! Every backend returns the raw reply text; the search validates it the same way whoever
//! wrote it. A [`BackendError`] is a failed request: recorded and retried by the loop, except
//! the [fatal](BackendError::is_fatal) ones that no retry can fix (a refused key, a missing
//! program), which stop the search.

pub mod chat;
#[cfg(feature = "chat")]
pub mod chat_client;
pub mod command;
pub mod offline;

use crate::hpo::config::AgentSettings;
use crate::hpo::prompts::SearchView;

/// Which prompt a request answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    Plan,
    Propose,
}

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::Plan => "plan",
            Stage::Propose => "propose",
        }
    }
}

/// One request to the agent: the rendered prompt, and the state it was written from (the
/// offline proposer reads the state; the LLM backends read only the prompt).
pub struct AgentRequest<'a> {
    pub stage: Stage,
    pub prompt: &'a str,
    pub view: &'a SearchView<'a>,
}

/// An agent.
pub trait Backend {
    /// The reply to one request, as text.
    fn reply(&mut self, request: &AgentRequest<'_>) -> Result<String, BackendError>;
}

/// A request that got no usable reply. Messages never contain an API key.
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    #[error("no reply from {url} within {seconds} s")]
    Timeout { url: String, seconds: f64 },
    #[error("cannot reach {url}: {problem}")]
    Connection { url: String, problem: String },
    #[error("{url} answered HTTP {status}: {body}")]
    Status {
        url: String,
        status: u16,
        body: String,
    },
    #[error("{url}: the response is not a chat completion: {problem}")]
    Response { url: String, problem: String },
    #[error(
        "this binary was built without the `{feature}` cargo feature (on by default): rebuild \
         without --no-default-features, or use backend = \"command\" or \"offline\""
    )]
    NotBuilt { feature: &'static str },
    #[error("{url}: the request cannot be sent: {problem}; check [agent.chat] base_url")]
    Request { url: String, problem: String },
    #[error(
        "the environment variable {var} named by [agent.chat] api_key_env is not set; export \
         it with the API key"
    )]
    MissingKey { var: String },
    #[error("cannot start `{program}`: {problem}; check [agent.command] argv")]
    Spawn { program: String, problem: String },
    #[error("`{program}` exited with {status}; stderr: {stderr}")]
    Exit {
        program: String,
        status: String,
        stderr: String,
    },
    #[error("`{program}` gave no reply within {seconds} s and was stopped")]
    CommandTimeout { program: String, seconds: f64 },
    #[error("`{program}`: {problem}")]
    CommandIo { program: String, problem: String },
}

impl BackendError {
    /// No retry can help: the service refused the request itself (4xx other than 408 and
    /// 429), the URL is malformed, the key or the program is missing.
    pub fn is_fatal(&self) -> bool {
        match self {
            BackendError::Status { status, .. } => {
                (400..500).contains(status) && *status != 408 && *status != 429
            }
            BackendError::Request { .. }
            | BackendError::MissingKey { .. }
            | BackendError::Spawn { .. } => true,
            _ => false,
        }
    }
}

/// The backend `[agent]` describes.
pub fn build_backend(settings: &AgentSettings) -> Result<Box<dyn Backend>, BackendError> {
    Ok(match settings {
        AgentSettings::Offline => Box::new(offline::OfflineProposer),
        #[cfg(feature = "chat")]
        AgentSettings::Chat(chat) => Box::new(chat_client::ChatBackend::new(chat.clone())?),
        #[cfg(not(feature = "chat"))]
        AgentSettings::Chat(_) => return Err(BackendError::NotBuilt { feature: "chat" }),
        AgentSettings::Command(command) => Box::new(command::CommandBackend::new(command.clone())),
    })
}

/// Exponential backoff: `initial × 2^attempt`, at most `max` (seconds).
#[cfg_attr(not(feature = "chat"), allow(dead_code))]
pub(crate) fn backoff(initial_s: f64, max_s: f64, attempt: u32) -> std::time::Duration {
    let seconds = (initial_s * 2f64.powi(attempt.min(30) as i32))
        .min(max_s)
        .max(0.0);
    std::time::Duration::from_secs_f64(seconds)
}

/// The last `max` characters of a text (error output is most useful at its end).
pub(crate) fn tail(text: &str, max: usize) -> String {
    let count = text.chars().count();
    if count <= max {
        text.trim().to_string()
    } else {
        let cut: String = text.chars().skip(count - max).collect();
        format!("...{}", cut.trim())
    }
}
