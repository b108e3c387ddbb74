//! An OpenAI-compatible chat-completions client: `POST {base_url}/chat/completions` with the
//! prompt as one user message. Timeouts, connection errors, 429 and 5xx are retried with
//! exponential backoff; other 4xx are not (they will not change on retry).
//!
//! The API key is read once from the environment variable the configuration names. It goes
//! into the `Authorization` header and nowhere else: error messages and replies are scrubbed
//! of it, in case a server echoes it back.

use serde::{Deserialize, Serialize};

/// `[agent.chat]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChatSettings {
    /// E.g. `https://api.openai.com/v1` or a local server's `http://127.0.0.1:8000/v1`.
    pub base_url: String,
    pub model: String,
    /// The environment variable holding the API key (no key is sent when absent).
    pub api_key_env: Option<String>,
    pub temperature: Option<f64>,
    /// Seconds allowed to one request, reply included.
    #[serde(default = "defaults::timeout_s")]
    pub timeout_s: f64,
    /// Retries after the first try.
    #[serde(default = "defaults::retries")]
    pub retries: u32,
    #[serde(default = "defaults::backoff_initial_s")]
    pub backoff_initial_s: f64,
    #[serde(default = "defaults::backoff_max_s")]
    pub backoff_max_s: f64,
}

mod defaults {
    pub fn timeout_s() -> f64 {
        600.0
    }
    pub fn retries() -> u32 {
        4
    }
    pub fn backoff_initial_s() -> f64 {
        2.0
    }
    pub fn backoff_max_s() -> f64 {
        60.0
    }
}

impl ChatSettings {
    pub(crate) fn check(&self) -> Result<(), String> {
        if !(self.base_url.starts_with("http://") || self.base_url.starts_with("https://")) {
            return Err(format!(
                "[agent.chat] base_url {:?} must start with http:// or https://",
                self.base_url
            ));
        }
        if self.model.trim().is_empty() {
            return Err("[agent.chat] model is empty".to_string());
        }
        if !(self.timeout_s.is_finite() && self.timeout_s > 0.0) {
            return Err("[agent.chat] timeout_s must be a positive number of seconds".to_string());
        }
        if !(self.backoff_initial_s >= 0.0 && self.backoff_max_s >= 0.0) {
            return Err(
                "[agent.chat] backoff_initial_s and backoff_max_s must be >= 0".to_string(),
            );
        }
        Ok(())
    }

    #[cfg_attr(not(feature = "chat"), allow(dead_code))]
    pub(crate) fn url(&self) -> String {
        format!("{}/chat/completions", self.base_url.trim_end_matches('/'))
    }
}
