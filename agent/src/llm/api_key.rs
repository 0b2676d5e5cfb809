//! The API key, sent in the `Authorization` header and nowhere else, and the [`Secrets`] of an
//! endpoint that are scrubbed from every text shown or stored.

use std::fmt;

/// Shown wherever a key would have appeared.
pub const REDACTED: &str = "[REDACTED]";

/// A bearer token. Its `Debug` form is redacted and it has no `Display`, so it cannot reach a log
/// line or an error message by accident; [`ApiKey::scrub`] removes it from text that came back
/// from a server (some echo the request in their errors).
#[derive(Clone, PartialEq, Eq)]
pub struct ApiKey(String);

impl ApiKey {
    /// The key, `None` when blank (an empty `OPENAI_API_KEY` means no key).
    pub fn new(key: impl Into<String>) -> Option<Self> {
        let key = key.into().trim().to_owned();
        (!key.is_empty()).then_some(ApiKey(key))
    }

    /// The secret itself, for the `Authorization` header only.
    pub(crate) fn expose(&self) -> &str {
        &self.0
    }

    /// `text` with every occurrence of the key, in any letter case, replaced by [`REDACTED`].
    pub fn scrub(&self, text: &str) -> String {
        redact(text, &self.0)
    }
}

impl fmt::Debug for ApiKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ApiKey({REDACTED})")
    }
}

/// `text` scrubbed of `key` when there is one.
pub fn scrub(key: Option<&ApiKey>, text: &str) -> String {
    match key {
        Some(key) => key.scrub(text),
        None => text.to_owned(),
    }
}

/// Every secret of an endpoint: the API key and the user info and query values of its base URL
/// ([`super::BaseUrl::secrets`]). Servers echo them back in any letter case (`bearer sk-…`), so
/// they are matched ignoring ASCII case.
#[derive(Clone, Default, PartialEq, Eq)]
pub struct Secrets(Vec<String>);

impl Secrets {
    /// The secrets `key` and `others`, blank ones left out.
    pub fn new(key: Option<&ApiKey>, others: impl IntoIterator<Item = String>) -> Self {
        let mut secrets: Vec<String> =
            key.map(|key| key.0.clone()).into_iter().chain(others).filter(|s| !s.trim().is_empty()).collect();
        // Longest first, so that a secret containing another is replaced whole.
        secrets.sort_by_key(|secret| std::cmp::Reverse(secret.len()));
        secrets.dedup();
        Secrets(secrets)
    }

    /// `text` with every secret, in any letter case, replaced by [`REDACTED`].
    pub fn scrub(&self, text: &str) -> String {
        self.0.iter().fold(text.to_owned(), |text, secret| redact(&text, secret))
    }
}

impl fmt::Debug for Secrets {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Secrets({} × {REDACTED})", self.0.len())
    }
}

/// `text` with every occurrence of `secret`, ignoring ASCII case, replaced by [`REDACTED`].
fn redact(text: &str, secret: &str) -> String {
    if secret.is_empty() {
        return text.to_owned();
    }
    let mut redacted = String::with_capacity(text.len());
    let mut copied = 0;
    for (at, _) in text.char_indices() {
        if at < copied {
            continue;
        }
        let end = at + secret.len();
        if text.get(at..end).is_some_and(|candidate| candidate.eq_ignore_ascii_case(secret)) {
            redacted.push_str(&text[copied..at]);
            redacted.push_str(REDACTED);
            copied = end;
        }
    }
    redacted.push_str(&text[copied..]);
    redacted
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn debug_is_redacted_and_scrub_removes_the_key_in_any_case() {
        let key = ApiKey::new("  sk-Secret-123 ").unwrap();
        assert_eq!(format!("{key:?}"), "ApiKey([REDACTED])");
        assert_eq!(key.expose(), "sk-Secret-123");
        assert_eq!(key.scrub("bad key sk-Secret-123!"), "bad key [REDACTED]!");
        assert_eq!(key.scrub("bearer sk-secret-123, SK-SECRET-1234"), "bearer [REDACTED], [REDACTED]4");
        assert_eq!(key.scrub("só sk-secret-12"), "só sk-secret-12");
        assert_eq!(scrub(None, "sk-secret-123"), "sk-secret-123");
        assert!(ApiKey::new("  ").is_none());
    }

    #[test]
    fn secrets_scrub_every_secret_and_do_not_show_in_debug() {
        let key = ApiKey::new("sk-key-AAAA").unwrap();
        let secrets = Secrets::new(Some(&key), ["pass-BBBB".to_owned(), " ".to_owned(), "pass-BBBB-longer".to_owned()]);
        assert_eq!(
            secrets.scrub("Bearer SK-KEY-aaaa, user:pass-bbbb-LONGER@host, pass-BBBB"),
            "Bearer [REDACTED], user:[REDACTED]@host, [REDACTED]"
        );
        assert_eq!(format!("{secrets:?}"), "Secrets(3 × [REDACTED])");
        assert_eq!(Secrets::default().scrub("text"), "text");
    }
}
