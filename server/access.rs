//! Who a match or an uploaded map belongs to: the secret its creator was given, and the
//! client it came from (for per-client quotas); the token bucket those quotas' rates use.

use std::net::{IpAddr, Ipv6Addr};
use std::time::{Duration, Instant};

/// One client for quotas and rate limits: an IPv4 address, or an IPv6 /64. A single
/// IPv6 subscriber is usually handed a whole /64, so keying on the full address would give
/// them 2^64 fresh budgets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ClientKey(IpAddr);

impl ClientKey {
    pub fn of(ip: IpAddr) -> ClientKey {
        match ip {
            IpAddr::V4(v4) => ClientKey(IpAddr::V4(v4)),
            IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
                // A dual-stack socket reports IPv4 clients as ::ffff:a.b.c.d.
                Some(v4) => ClientKey(IpAddr::V4(v4)),
                None => {
                    let s = v6.segments();
                    ClientKey(IpAddr::V6(Ipv6Addr::new(
                        s[0], s[1], s[2], s[3], 0, 0, 0, 0,
                    )))
                }
            },
        }
    }
}

/// A token bucket: `capacity` units at once, refilled at `rate` per second. One bucket
/// type serves every rate the server keeps (requests and WebSocket messages per client,
/// path-search work per client and server-wide).
#[derive(Debug, Clone)]
pub struct Bucket {
    units: f64,
    capacity: f64,
    rate: f64,
    last: Instant,
}

impl Bucket {
    pub fn new(capacity: f64, rate: f64) -> Bucket {
        Bucket {
            units: capacity,
            capacity,
            rate,
            last: Instant::now(),
        }
    }

    /// Adds what the rate gave since the last refill, up to the capacity.
    pub fn refill(&mut self, now: Instant) {
        self.units = (self.units + (now - self.last).as_secs_f64() * self.rate).min(self.capacity);
        self.last = now;
    }

    /// Seconds until `units` are there (0 when they are), as of the last refill.
    pub fn wait_s(&self, units: f64) -> f64 {
        ((units - self.units) / self.rate).max(0.0)
    }

    /// Takes `units` without looking: for a caller that checked [`Bucket::wait_s`] on this
    /// bucket and another before taking from both.
    pub fn spend(&mut self, units: f64) {
        self.units -= units;
    }

    /// How long since it was last refilled (last used).
    pub fn idle(&self, now: Instant) -> Duration {
        now - self.last
    }

    /// Whether it is full (as of the last refill): nothing to remember about its client.
    pub fn is_full(&self) -> bool {
        self.units >= self.capacity
    }

    /// Takes one unit if there is one; otherwise says how long until there will be.
    pub fn take(&mut self) -> Result<(), Duration> {
        self.refill(Instant::now());
        if self.units >= 1.0 {
            self.spend(1.0);
            Ok(())
        } else {
            Err(Duration::from_secs_f64(self.wait_s(1.0)))
        }
    }
}

impl ClientKey {
    /// The key its [`Display`](std::fmt::Display) wrote (a stored match's client); `None`
    /// for anything else.
    pub fn parse(text: &str) -> Option<ClientKey> {
        let ip: IpAddr = text.strip_suffix("/64").unwrap_or(text).parse().ok()?;
        Some(ClientKey::of(ip))
    }
}

impl std::fmt::Display for ClientKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            IpAddr::V4(v4) => write!(f, "{v4}"),
            IpAddr::V6(v6) => write!(f, "{v6}/64"),
        }
    }
}

/// A secret as the server keeps it: its SHA-256, so that what is stored (a match's owner
/// and seat tokens in the history, to resume it after a restart) lets nobody in who copies
/// the database. Tokens are 96 to 192 random bits, so an unsalted hash is enough: nothing
/// guessable is behind it.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct SecretHash([u8; 32]);

impl SecretHash {
    pub fn of(secret: &str) -> SecretHash {
        use sha2::Digest;
        SecretHash(sha2::Sha256::digest(secret.as_bytes()).into())
    }

    /// Whether `presented` is the secret this is the hash of (in time independent of where
    /// the hashes differ).
    pub fn matches(&self, presented: &str) -> bool {
        let other = SecretHash::of(presented);
        self.0
            .iter()
            .zip(other.0.iter())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0
    }

    /// Lower-case hex, as stored.
    pub fn to_hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// The hash written by [`SecretHash::to_hex`]; `None` for anything else.
    pub fn from_hex(hex: &str) -> Option<SecretHash> {
        if hex.len() != 64 || !hex.is_ascii() {
            return None;
        }
        let mut out = [0u8; 32];
        for (i, b) in out.iter_mut().enumerate() {
            *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()?;
        }
        Some(SecretHash(out))
    }
}

impl std::fmt::Debug for SecretHash {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SecretHash(..)")
    }
}

/// Who may change a match or a map, and who made it.
#[derive(Debug, Clone, Default)]
pub struct Owner {
    /// The hash of the secret that was handed out when it was made; `None` for what the
    /// server made itself (the showcase, shipped maps), which only the operator may change.
    pub token: Option<SecretHash>,
    /// The client that made it; `None` for the server's own.
    pub client: Option<ClientKey>,
    /// Whether the token also reads the match live and sees its secret seed. Not for a
    /// rated match (docs/ratings.md): whoever made it may be the person playing it.
    pub reads_live: bool,
}

impl Owner {
    /// A fresh owner for something `client` makes now (`None`: the operator, whose matches
    /// count against no client's quota), and its token: the only time the server holds it
    /// in clear.
    pub fn new(client: Option<ClientKey>) -> (Owner, String) {
        let token = random_id(16);
        let owner = Owner {
            token: Some(SecretHash::of(&token)),
            client,
            reads_live: true,
        };
        (owner, token)
    }

    /// Whether `presented` is this owner's token.
    pub fn is(&self, presented: &str) -> bool {
        self.token.is_some_and(|t| t.matches(presented))
    }
}

/// A fresh random identifier of `bytes` random bytes, hex-encoded (ids and secret tokens).
pub fn random_id(bytes: usize) -> String {
    let mut buf = vec![0u8; bytes];
    if getrandom::fill(&mut buf).is_err() {
        // The OS RNG failing is not something to limp on with predictable tokens.
        panic!("the operating system's random number generator failed");
    }
    buf.iter().map(|b| format!("{b:02x}")).collect()
}

/// A fresh secret seed for a match people may join, from the operating system's random
/// source: 63 bits, so that clients that read integers as signed 64-bit ones hold it.
pub fn random_seed() -> u64 {
    let mut buf = [0u8; 8];
    if getrandom::fill(&mut buf).is_err() {
        // A guessable seed would let anyone rebuild the match: no limping on.
        panic!("the operating system's random number generator failed");
    }
    u64::from_le_bytes(buf) >> 1
}

/// Compares secrets in time independent of where they differ.
pub fn same_secret(a: &str, b: &str) -> bool {
    a.len() == b.len()
        && a.bytes()
            .zip(b.bytes())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ipv6_clients_are_keyed_by_their_64() {
        let a: IpAddr = "2001:db8:1:2:aaaa::1".parse().unwrap();
        let b: IpAddr = "2001:db8:1:2:ffff:1:2:3".parse().unwrap();
        let c: IpAddr = "2001:db8:1:3::1".parse().unwrap();
        assert_eq!(ClientKey::of(a), ClientKey::of(b));
        assert_ne!(ClientKey::of(a), ClientKey::of(c));
        assert_eq!(ClientKey::of(a).to_string(), "2001:db8:1:2::/64");
        let mapped: IpAddr = "::ffff:192.0.2.7".parse().unwrap();
        assert_eq!(
            ClientKey::of(mapped),
            ClientKey::of("192.0.2.7".parse().unwrap())
        );
        assert_ne!(
            ClientKey::of("192.0.2.7".parse().unwrap()),
            ClientKey::of("192.0.2.8".parse().unwrap())
        );
        for key in [ClientKey::of(a), ClientKey::of(mapped)] {
            assert_eq!(ClientKey::parse(&key.to_string()), Some(key));
        }
        assert_eq!(ClientKey::parse("nowhere"), None);
    }

    #[test]
    fn secrets_compare_whole() {
        assert!(same_secret("abcd", "abcd"));
        assert!(!same_secret("abcd", "abce"));
        assert!(!same_secret("abcd", "abc"));
        let (owner, token) = Owner::new(Some(ClientKey::of("192.0.2.7".parse().unwrap())));
        assert_eq!(token.len(), 32);
        assert!(owner.is(&token) && !owner.is("") && !Owner::default().is(""));
        let hash = owner.token.unwrap();
        assert_eq!(SecretHash::from_hex(&hash.to_hex()), Some(hash));
        assert_eq!(SecretHash::from_hex("zz"), None);
        assert!(!format!("{owner:?}").contains(&hash.to_hex()));
    }
}
