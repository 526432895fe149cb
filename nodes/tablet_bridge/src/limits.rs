//! The small guards of the bridge: a token bucket (per-connection message rate, wrong-PIN
//! budget) driven by an injected clock, and a PIN comparison whose time does not depend on
//! where a guess first differs.

use std::time::Duration;
use subtle::ConstantTimeEq;

/// A token bucket: `capacity` tokens, refilled at `per_second`; time comes from the caller.
#[derive(Debug, Clone)]
pub struct TokenBucket {
    capacity: f64,
    per_second: f64,
    tokens: f64,
    last: Duration,
}

impl TokenBucket {
    /// A full bucket at time `now`.
    pub fn new(capacity: f64, per_second: f64, now: Duration) -> Self {
        TokenBucket {
            capacity,
            per_second,
            tokens: capacity,
            last: now,
        }
    }

    fn refill(&mut self, now: Duration) {
        // A clock that steps back refills nothing rather than draining or overflowing.
        let elapsed = now.saturating_sub(self.last).as_secs_f64();
        self.tokens = (self.tokens + elapsed * self.per_second).min(self.capacity);
        self.last = self.last.max(now);
    }

    /// Whether a token is there at `now`, without taking it.
    pub fn has_token(&mut self, now: Duration) -> bool {
        self.refill(now);
        self.tokens >= 1.0
    }

    /// Takes a token if there is one.
    pub fn try_take(&mut self, now: Duration) -> bool {
        if self.has_token(now) {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }

    /// Seconds until the next token.
    pub fn wait_secs(&mut self, now: Duration) -> f64 {
        self.refill(now);
        ((1.0 - self.tokens) / self.per_second).max(0.0)
    }
}

/// Whether `guess` is the PIN. Equal-length inputs take the same time whatever they hold, so
/// timing tells an attacker nothing about which characters were right.
pub fn pin_matches(guess: &str, pin: &str) -> bool {
    bool::from(guess.as_bytes().ct_eq(pin.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn bucket_allows_a_burst_then_the_sustained_rate() {
        let mut b = TokenBucket::new(3.0, 2.0, ms(0));
        assert!((0..3).all(|_| b.try_take(ms(0))));
        assert!(!b.try_take(ms(0)));
        assert!(!b.try_take(ms(400)), "0.8 tokens after 400 ms");
        assert!(b.try_take(ms(500)));
        assert!(!b.try_take(ms(500)));
        // A long quiet spell refills only up to the capacity.
        assert!((0..3).all(|_| b.try_take(ms(60_000))));
        assert!(!b.try_take(ms(60_000)));
        assert!((b.wait_secs(ms(60_000)) - 0.5).abs() < 1e-9);
    }

    #[test]
    fn bucket_survives_a_clock_that_steps_back() {
        let mut b = TokenBucket::new(1.0, 1.0, ms(10_000));
        assert!(b.try_take(ms(10_000)));
        assert!(!b.try_take(ms(5_000)));
        assert!(!b.try_take(ms(10_500)));
        assert!(b.try_take(ms(11_000)));
    }

    #[test]
    fn has_token_does_not_take() {
        let mut b = TokenBucket::new(1.0, 1.0, ms(0));
        assert!(b.has_token(ms(0)));
        assert!(b.has_token(ms(0)));
        assert!(b.try_take(ms(0)));
        assert!(!b.has_token(ms(0)));
    }

    #[test]
    fn pin_compare_is_exact() {
        assert!(pin_matches("1234", "1234"));
        assert!(!pin_matches("1235", "1234"));
        assert!(!pin_matches("123", "1234"));
        assert!(!pin_matches("12345", "1234"));
        assert!(!pin_matches("", "1234"));
        assert!(pin_matches("pä55", "pä55"));
    }
}
