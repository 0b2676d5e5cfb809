//! When to try an HTTP request again and how long to wait: bounded retries with exponential
//! backoff, or the server's own `Retry-After` when it sends one.

use std::time::{Duration, SystemTime};

use reqwest::header::HeaderMap;

/// Retries of a failed request (429, 5xx, connection errors, timeouts).
#[derive(Debug, Clone, PartialEq)]
pub struct RetryPolicy {
    /// Retries after the first attempt (0: one attempt only).
    pub max_retries: u32,
    /// Wait before the first retry; doubled for each further one.
    pub initial_backoff: Duration,
    /// Longest backoff wait.
    pub max_backoff: Duration,
    /// Longest `Retry-After` honoured; a server asking for more gets a clear error instead.
    pub max_retry_after: Duration,
}

impl Default for RetryPolicy {
    /// 3 retries, 1 s doubling to at most 20 s, `Retry-After` up to 120 s.
    fn default() -> Self {
        RetryPolicy {
            max_retries: 3,
            initial_backoff: Duration::from_secs(1),
            max_backoff: Duration::from_secs(20),
            max_retry_after: Duration::from_secs(120),
        }
    }
}

impl RetryPolicy {
    /// Backoff before retry number `retry` (0-based): `initial · 2^retry`, at most `max_backoff`.
    pub fn backoff(&self, retry: u32) -> Duration {
        let factor = 2u32.saturating_pow(retry.min(30));
        self.initial_backoff.saturating_mul(factor).min(self.max_backoff)
    }

    /// The wait before retry number `retry` when `left` of the request's waiting time remains
    /// (the request timeout less the waits so far): the server's `Retry-After` when given (an
    /// error, the wait it asked for, when that exceeds `left` or `max_retry_after`), else the
    /// backoff, cut to `left`.
    pub fn wait(&self, retry: u32, retry_after: Option<Duration>, left: Duration) -> Result<Duration, Duration> {
        match retry_after {
            Some(wait) if wait > self.max_retry_after.min(left) => Err(wait),
            Some(wait) => Ok(wait),
            None => Ok(self.backoff(retry).min(left)),
        }
    }
}

/// The wait a response asks for: `retry-after-ms` (OpenAI) or `Retry-After` in seconds or as an
/// HTTP date (RFC 9110 §10.2.3). `None` when absent or unreadable.
pub fn retry_after(headers: &HeaderMap) -> Option<Duration> {
    let header = |name: &str| headers.get(name).and_then(|value| value.to_str().ok()).map(str::trim);
    if let Some(ms) = header("retry-after-ms").and_then(|v| v.parse::<f64>().ok()) {
        return seconds(ms / 1000.0);
    }
    let value = header("retry-after")?;
    if let Ok(secs) = value.parse::<f64>() {
        return seconds(secs);
    }
    let at = httpdate::parse_http_date(value).ok()?;
    Some(at.duration_since(SystemTime::now()).unwrap_or(Duration::ZERO))
}

fn seconds(secs: f64) -> Option<Duration> {
    Duration::try_from_secs_f64(secs).ok()
}

#[cfg(test)]
mod tests {
    use reqwest::header::HeaderValue;

    use super::*;

    fn headers(pairs: &[(&'static str, &str)]) -> HeaderMap {
        let mut map = HeaderMap::new();
        for (name, value) in pairs {
            map.insert(*name, HeaderValue::from_str(value).unwrap());
        }
        map
    }

    #[test]
    fn backoff_doubles_up_to_the_cap() {
        let policy = RetryPolicy::default();
        let waits: Vec<u64> = (0..7).map(|retry| policy.backoff(retry).as_secs()).collect();
        assert_eq!(waits, [1, 2, 4, 8, 16, 20, 20]);
        assert_eq!(policy.backoff(u32::MAX), Duration::from_secs(20));
    }

    #[test]
    fn retry_after_reads_seconds_milliseconds_and_dates() {
        assert_eq!(retry_after(&headers(&[("retry-after", "3")])), Some(Duration::from_secs(3)));
        assert_eq!(retry_after(&headers(&[("retry-after", " 0.5 ")])), Some(Duration::from_millis(500)));
        let both = headers(&[("retry-after", "3"), ("retry-after-ms", "250")]);
        assert_eq!(retry_after(&both), Some(Duration::from_millis(250)));
        let later = httpdate::fmt_http_date(SystemTime::now() + Duration::from_secs(30));
        let wait = retry_after(&headers(&[("retry-after", &later)])).unwrap();
        assert!(wait > Duration::from_secs(25) && wait <= Duration::from_secs(30), "{wait:?}");
        let past = httpdate::fmt_http_date(SystemTime::now() - Duration::from_secs(30));
        assert_eq!(retry_after(&headers(&[("retry-after", &past)])), Some(Duration::ZERO));
        for bad in ["soon", "-1", "NaN"] {
            assert_eq!(retry_after(&headers(&[("retry-after", bad)])), None, "{bad}");
        }
        assert_eq!(retry_after(&HeaderMap::new()), None);
    }

    #[test]
    fn wait_prefers_retry_after_and_refuses_long_ones() {
        let policy = RetryPolicy::default();
        let left = Duration::from_secs(180);
        assert_eq!(policy.wait(2, None, left), Ok(Duration::from_secs(4)));
        assert_eq!(policy.wait(2, Some(Duration::from_secs(7)), left), Ok(Duration::from_secs(7)));
        assert_eq!(policy.wait(0, Some(Duration::from_secs(3600)), left), Err(Duration::from_secs(3600)));
    }

    #[test]
    fn waits_are_bounded_by_the_time_left() {
        let policy = RetryPolicy::default();
        let left = Duration::from_secs(5);
        assert_eq!(policy.wait(0, Some(Duration::from_secs(100)), left), Err(Duration::from_secs(100)));
        assert_eq!(policy.wait(0, Some(left), left), Ok(left));
        assert_eq!(policy.wait(4, None, left), Ok(left), "a 16 s backoff is cut to what is left");
        assert_eq!(policy.wait(0, None, Duration::ZERO), Ok(Duration::ZERO));
    }
}
