//! Who a match or an uploaded map belongs to: the secret its creator was given, and the
//! client it came from (for per-client quotas).

use std::net::{IpAddr, Ipv6Addr};

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

impl std::fmt::Display for ClientKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            IpAddr::V4(v4) => write!(f, "{v4}"),
            IpAddr::V6(v6) => write!(f, "{v6}/64"),
        }
    }
}

/// Who may change a match or a map, and who made it.
#[derive(Debug, Clone, Default)]
pub struct Owner {
    /// The secret that was handed out when it was made; `None` for what the server made
    /// itself (the showcase, shipped maps), which only the operator may change.
    pub token: Option<String>,
    /// The client that made it; `None` for the server's own.
    pub client: Option<ClientKey>,
}

impl Owner {
    /// A fresh owner for something `client` makes now (`None`: the operator, whose matches
    /// count against no client's quota); the token is in `owner.token`.
    pub fn new(client: Option<ClientKey>) -> Owner {
        Owner {
            token: Some(random_id(16)),
            client,
        }
    }

    /// Whether `presented` is this owner's token.
    pub fn is(&self, presented: &str) -> bool {
        self.token
            .as_deref()
            .is_some_and(|t| same_secret(t, presented))
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
    }

    #[test]
    fn secrets_compare_whole() {
        assert!(same_secret("abcd", "abcd"));
        assert!(!same_secret("abcd", "abce"));
        assert!(!same_secret("abcd", "abc"));
        let owner = Owner::new(Some(ClientKey::of("192.0.2.7".parse().unwrap())));
        let token = owner.token.clone().unwrap();
        assert_eq!(token.len(), 32);
        assert!(owner.is(&token) && !owner.is("") && !Owner::default().is(""));
    }
}
