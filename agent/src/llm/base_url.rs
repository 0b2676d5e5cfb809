//! The base URL of an endpoint, parsed once. Its user info (`http://user:key@host/v1`) and query
//! values (`?api_key=…`) are secrets: they travel in requests but every printed form redacts them.

use std::fmt;

use reqwest::Url;

use super::api_key::REDACTED;
use super::error::LlmError;

/// Secrets of a URL shorter than this are not scrubbed from server text: they are not keys
/// (`?api-version=1`, user `me`), and scrubbing them would garble unrelated words. The printed
/// URL redacts them all the same.
const MIN_SCRUBBED_CHARS: usize = 8;

/// An `http` or `https` URL up to the API version, e.g. `https://api.openai.com/v1`. Its
/// `Display` and `Debug` forms redact user info and query values.
#[derive(Clone, PartialEq, Eq)]
pub struct BaseUrl(Url);

impl BaseUrl {
    /// Parses `text`; errors say why without repeating it (it may hold a key).
    pub fn parse(text: &str) -> Result<Self, LlmError> {
        let invalid = |reason: String| LlmError::BaseUrl { reason };
        let url = Url::parse(text.trim()).map_err(|error| invalid(error.to_string()))?;
        if !matches!(url.scheme(), "http" | "https") {
            let scheme = url.scheme();
            return Err(invalid(format!(
                "the scheme is `{scheme}`, not http or https (e.g. http://localhost:8000/v1)"
            )));
        }
        if url.cannot_be_a_base() || url.host_str().is_none() {
            return Err(invalid("it names no host".to_owned()));
        }
        Ok(BaseUrl(url))
    }

    /// The chat-completions URL: the path segments `chat/completions` appended to the base
    /// path, the query string kept after them.
    pub fn chat_completions(&self) -> Url {
        let mut url = self.0.clone();
        url.set_fragment(None);
        // `parse` accepted only URLs that can be a base, for which this is always `Ok`.
        if let Ok(mut segments) = url.path_segments_mut() {
            segments.pop_if_empty().extend(["chat", "completions"]);
        }
        url
    }

    /// The URL as parsed (secrets included), for deciding what kind of server it is.
    pub fn as_str(&self) -> &str {
        self.0.as_str()
    }

    /// The user name, password and query values, as written and percent-decoded, for
    /// [`super::api_key::Secrets`].
    pub fn secrets(&self) -> Vec<String> {
        let url = &self.0;
        let query_values = url.query_pairs().map(|(_, value)| value.into_owned());
        let raw_query_values = url
            .query()
            .into_iter()
            .flat_map(|query| query.split('&'))
            .filter_map(|pair| pair.split_once('=').map(|(_, value)| value.to_owned()));
        let user = [url.username(), url.password().unwrap_or("")].map(str::to_owned);
        let decoded_user = user.clone().map(|part| decode(&part));
        let mut secrets: Vec<String> = user
            .into_iter()
            .chain(decoded_user)
            .chain(query_values)
            .chain(raw_query_values)
            .filter(|secret| secret.chars().count() >= MIN_SCRUBBED_CHARS)
            .collect();
        secrets.sort();
        secrets.dedup();
        secrets
    }
}

impl fmt::Display for BaseUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&redacted(&self.0))
    }
}

impl fmt::Debug for BaseUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "BaseUrl({self})")
    }
}

/// `url` for printing: user info replaced by one `[REDACTED]@`, each query value by
/// `[REDACTED]` (the names stay: they say what was given), the fragment left out.
pub fn redacted(url: &Url) -> String {
    let mut bare = url.clone();
    // Removing user info fails only for URLs without a host, which carry none.
    let _ = bare.set_username("");
    let _ = bare.set_password(None);
    bare.set_query(None);
    bare.set_fragment(None);
    let mut shown = bare.to_string();
    if !url.username().is_empty() || url.password().is_some() {
        if let Some(at) = shown.find("://") {
            shown.insert_str(at + 3, &format!("{REDACTED}@"));
        }
    }
    if let Some(query) = url.query() {
        let pairs: Vec<String> = query
            .split('&')
            .map(|pair| match pair.split_once('=') {
                Some((name, _)) => format!("{name}={REDACTED}"),
                None => pair.to_owned(),
            })
            .collect();
        shown.push('?');
        shown.push_str(&pairs.join("&"));
    }
    shown
}

/// `text` percent-decoded (lossy), as a server that decoded the URL would echo it.
fn decode(text: &str) -> String {
    Url::parse(&format!("http://h/?v={text}"))
        .ok()
        .and_then(|url| url.query_pairs().next().map(|(_, value)| value.into_owned()))
        .unwrap_or_else(|| text.to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_path_is_joined_by_segments_and_the_query_stays_a_query() {
        let url = |base: &str| BaseUrl::parse(base).unwrap().chat_completions().to_string();
        assert_eq!(url("http://localhost:8000/v1/"), "http://localhost:8000/v1/chat/completions");
        assert_eq!(url(super::super::OPENAI_BASE_URL), "https://api.openai.com/v1/chat/completions");
        assert_eq!(url("http://localhost:8000"), "http://localhost:8000/chat/completions");
        assert_eq!(
            url("https://x.openai.azure.com/openai/deployments/d?api-version=2024-06-01#top"),
            "https://x.openai.azure.com/openai/deployments/d/chat/completions?api-version=2024-06-01"
        );
    }

    #[test]
    fn user_info_and_query_values_are_redacted_when_shown_and_listed_as_secrets() {
        let base = BaseUrl::parse(" http://me:sk-pass%2Fword@[::1]:8000/v1?api_key=sk-query-123&v=1&flag ").unwrap();
        assert_eq!(base.to_string(), "http://[REDACTED]@[::1]:8000/v1?api_key=[REDACTED]&v=[REDACTED]&flag");
        assert_eq!(
            format!("{base:?}"),
            "BaseUrl(http://[REDACTED]@[::1]:8000/v1?api_key=[REDACTED]&v=[REDACTED]&flag)"
        );
        assert_eq!(base.secrets(), ["sk-pass%2Fword", "sk-pass/word", "sk-query-123"]);
        let plain = BaseUrl::parse("https://api.deepseek.com/v1").unwrap();
        assert_eq!(plain.to_string(), "https://api.deepseek.com/v1");
        assert!(plain.secrets().is_empty());
        assert_eq!(redacted(&plain.chat_completions()), "https://api.deepseek.com/v1/chat/completions");
    }

    #[test]
    fn bad_base_urls_say_why_without_repeating_the_url() {
        for (text, reason) in [
            ("localhost:8000/v1", "the scheme is `localhost`"),
            ("ftp://user:sk-secret@host/v1", "the scheme is `ftp`"),
            ("api.openai.com/v1", "relative URL without a base"),
            ("http://host:99999/v1", "invalid port number"),
        ] {
            let error = BaseUrl::parse(text).unwrap_err().to_string();
            assert!(error.contains(reason) && !error.contains("secret"), "{text}: {error}");
        }
    }
}
