//! The chat-completions client of [`super::chat`] (cargo feature `chat`, on by default: a
//! binary built without it has no HTTP or TLS stack and rejects `backend = "chat"`).

use std::time::Duration;

use crate::hpo::backend::chat::ChatSettings;
use crate::hpo::backend::{AgentRequest, Backend, BackendError, backoff, tail};

/// Responses larger than this are refused (a chat reply is a few kilobytes).
const MAX_RESPONSE_BYTES: u64 = 8 * 1024 * 1024;

/// The chat-completions backend.
pub struct ChatBackend {
    settings: ChatSettings,
    key: Option<String>,
    agent: ureq::Agent,
    url: String,
}

impl ChatBackend {
    /// Reads the API key from the environment; fails when the named variable is unset.
    pub fn new(settings: ChatSettings) -> Result<Self, BackendError> {
        let key = match &settings.api_key_env {
            None => None,
            Some(var) => match std::env::var(var) {
                Ok(key) if !key.trim().is_empty() => Some(key.trim().to_string()),
                _ => return Err(BackendError::MissingKey { var: var.clone() }),
            },
        };
        let config = ureq::Agent::config_builder()
            .timeout_global(Some(Duration::from_secs_f64(settings.timeout_s)))
            .http_status_as_error(false)
            .build();
        Ok(ChatBackend {
            url: settings.url(),
            settings,
            key,
            agent: config.into(),
        })
    }

    /// Replaces the key wherever a server or a library put it.
    fn scrub(&self, text: &str) -> String {
        match &self.key {
            Some(key) if key.len() >= 4 => text.replace(key.as_str(), "[api key]"),
            _ => text.to_string(),
        }
    }

    fn body(&self, prompt: &str) -> String {
        let mut body = serde_json::json!({
            "model": self.settings.model,
            "messages": [{"role": "user", "content": prompt}],
        });
        if let (Some(t), Some(map)) = (self.settings.temperature, body.as_object_mut()) {
            map.insert("temperature".to_string(), serde_json::Value::from(t));
        }
        body.to_string()
    }

    /// One try.
    fn post(&self, body: &str) -> Result<String, BackendError> {
        let mut request = self
            .agent
            .post(&self.url)
            .header("Content-Type", "application/json");
        if let Some(key) = &self.key {
            request = request.header("Authorization", format!("Bearer {key}"));
        }
        let mut response = request.send(body).map_err(|e| self.transport_error(e))?;
        let status = response.status().as_u16();
        let text = response
            .body_mut()
            .with_config()
            .limit(MAX_RESPONSE_BYTES)
            .lossy_utf8(true)
            .read_to_string()
            .map_err(|e| self.transport_error(e))?;
        let text = self.scrub(&text);
        if !(200..300).contains(&status) {
            return Err(BackendError::Status {
                url: self.url.clone(),
                status,
                body: tail(&text, 300),
            });
        }
        message_content(&text).map_err(|problem| BackendError::Response {
            url: self.url.clone(),
            problem,
        })
    }

    fn transport_error(&self, error: ureq::Error) -> BackendError {
        let url = self.url.clone();
        match error {
            ureq::Error::Timeout(_) => BackendError::Timeout {
                url,
                seconds: self.settings.timeout_s,
            },
            ureq::Error::Io(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                BackendError::Timeout {
                    url,
                    seconds: self.settings.timeout_s,
                }
            }
            ureq::Error::BadUri(_) | ureq::Error::Http(_) => BackendError::Request {
                url,
                problem: self.scrub(&error.to_string()),
            },
            other => BackendError::Connection {
                url,
                problem: self.scrub(&other.to_string()),
            },
        }
    }
}

/// Timeouts, connection failures, 429 and 5xx are worth another try.
fn retryable(error: &BackendError) -> bool {
    match error {
        BackendError::Timeout { .. } | BackendError::Connection { .. } => true,
        BackendError::Status { status, .. } => *status == 429 || *status == 408 || *status >= 500,
        _ => false,
    }
}

impl Backend for ChatBackend {
    fn reply(&mut self, request: &AgentRequest<'_>) -> Result<String, BackendError> {
        let body = self.body(request.prompt);
        let mut attempt = 0;
        loop {
            match self.post(&body) {
                Ok(reply) => return Ok(reply),
                Err(error) if retryable(&error) && attempt < self.settings.retries => {
                    std::thread::sleep(backoff(
                        self.settings.backoff_initial_s,
                        self.settings.backoff_max_s,
                        attempt,
                    ));
                    attempt += 1;
                }
                Err(error) => return Err(error),
            }
        }
    }
}

/// `choices[0].message.content` of a chat completion: a string, or a list of text parts.
fn message_content(response: &str) -> Result<String, String> {
    let json: serde_json::Value =
        serde_json::from_str(response).map_err(|e| format!("not JSON ({e})"))?;
    let content = json
        .get("choices")
        .and_then(|c| c.get(0))
        .and_then(|c| c.get("message"))
        .and_then(|m| m.get("content"))
        .ok_or("no choices[0].message.content")?;
    match content {
        serde_json::Value::String(text) => Ok(text.clone()),
        serde_json::Value::Array(parts) => Ok(parts
            .iter()
            .filter_map(|p| p.get("text").and_then(serde_json::Value::as_str))
            .collect::<Vec<_>>()
            .join("")),
        serde_json::Value::Null => Ok(String::new()),
        _ => Err("choices[0].message.content is neither text nor a list of parts".to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn content_comes_from_the_first_choice() {
        let ok = r#"{"choices":[{"message":{"role":"assistant","content":"hi"}}]}"#;
        assert_eq!(message_content(ok).unwrap(), "hi");
        let parts = r#"{"choices":[{"message":{"content":[{"type":"text","text":"a"},{"type":"text","text":"b"}]}}]}"#;
        assert_eq!(message_content(parts).unwrap(), "ab");
        assert!(message_content(r#"{"error":"x"}"#).is_err());
        assert!(message_content("<html>").is_err());
    }

    #[test]
    fn only_transient_failures_are_retried() {
        let status = |status| BackendError::Status {
            url: String::new(),
            status,
            body: String::new(),
        };
        assert!(retryable(&status(500)) && retryable(&status(503)) && retryable(&status(429)));
        assert!(!retryable(&status(400)) && !retryable(&status(401)));
        assert!(status(401).is_fatal() && !status(500).is_fatal() && !status(429).is_fatal());
    }
}
