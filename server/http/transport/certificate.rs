//! The certificate WebTransport sessions are encrypted with: the operator's (`--tls-cert`,
//! `--tls-key`: PEM files), or one the server makes itself. Browsers accept a self-signed
//! certificate for WebTransport only when the page pins its hash (`serverCertificateHashes`),
//! and then only an ECDSA P-256 one valid for at most 14 days (Chromium refuses 15), so the
//! server's own lasts [`SELF_SIGNED_DAYS`] and is replaced every [`RENEW_EVERY`]: sessions
//! open keep theirs, new ones get the new one, whose hash `GET /api/transport` publishes.

use std::path::PathBuf;
use std::time::Duration;

use wtransport::Identity;
use wtransport::tls::self_signed::time::{Duration as Span, OffsetDateTime};

/// How long the server's own certificate is valid: under the browsers' 14 days, less the
/// hour it is dated back.
pub const SELF_SIGNED_DAYS: i64 = 13;
/// It is dated back this much, for clients whose clocks run a little late.
const BACKDATE_HOURS: i64 = 1;
/// How often the server's own certificate is replaced: well before it runs out, so that a
/// page that read the hash a while ago still connects with it for days.
pub const RENEW_EVERY: Duration = Duration::from_secs(6 * 24 * 3600);

/// Where the certificate comes from.
#[derive(Debug, Clone, Default)]
pub enum Source {
    /// Made by the server, renewed every [`RENEW_EVERY`].
    #[default]
    SelfSigned,
    /// The operator's PEM files: a certificate (chain) and its private key.
    Files { cert: PathBuf, key: PathBuf },
}

#[derive(Debug, thiserror::Error)]
pub enum CertificateError {
    #[error("making a self-signed certificate: {0}")]
    SelfSigned(String),
    #[error("reading the certificate {cert} and key {key}: {error}")]
    Files {
        cert: PathBuf,
        key: PathBuf,
        error: String,
    },
}

/// An identity and the SHA-256 hash of its leaf certificate (lowercase hex).
pub struct Certificate {
    pub identity: Identity,
    pub hash: String,
    /// Whether browsers may pin it by hash (the server's own): else the page trusts it as any
    /// HTTPS certificate.
    pub pinned: bool,
}

impl Source {
    /// A certificate from this source, now.
    pub async fn load(&self) -> Result<Certificate, CertificateError> {
        match self {
            Source::SelfSigned => self_signed(OffsetDateTime::now_utc()),
            Source::Files { cert, key } => {
                let identity = Identity::load_pemfiles(cert, key).await.map_err(|e| {
                    CertificateError::Files {
                        cert: cert.clone(),
                        key: key.clone(),
                        error: e.to_string(),
                    }
                })?;
                let hash = leaf_hash(&identity).ok_or_else(|| CertificateError::Files {
                    cert: cert.clone(),
                    key: key.clone(),
                    error: "the file holds no certificate".into(),
                })?;
                Ok(Certificate {
                    identity,
                    hash,
                    pinned: false,
                })
            }
        }
    }

    /// Whether the certificate is the server's own, to be renewed.
    pub fn renews(&self) -> bool {
        matches!(self, Source::SelfSigned)
    }
}

/// A self-signed ECDSA P-256 certificate valid from an hour before `now` for
/// [`SELF_SIGNED_DAYS`] days, for the names a local page reaches the server by.
fn self_signed(now: OffsetDateTime) -> Result<Certificate, CertificateError> {
    let identity = Identity::self_signed_builder()
        .subject_alt_names(["localhost", "127.0.0.1", "::1"])
        .not_before(now - Span::hours(BACKDATE_HOURS))
        .offset_from_not_before(Span::days(SELF_SIGNED_DAYS))
        .build()
        .map_err(|e| CertificateError::SelfSigned(e.to_string()))?;
    let hash = leaf_hash(&identity)
        .ok_or_else(|| CertificateError::SelfSigned("no certificate made".into()))?;
    Ok(Certificate {
        identity,
        hash,
        pinned: true,
    })
}

/// The SHA-256 hash of `identity`'s leaf certificate's DER, in lowercase hex.
fn leaf_hash(identity: &Identity) -> Option<String> {
    let leaf = identity.certificate_chain().as_slice().first()?;
    let digest = leaf.hash();
    let bytes: &[u8; 32] = digest.as_ref();
    Some(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_servers_own_certificate_is_pinnable_and_each_is_new() {
        let now = OffsetDateTime::now_utc();
        let a = self_signed(now).expect("made");
        let b = self_signed(now).expect("made");
        assert!(a.pinned);
        assert_eq!(a.hash.len(), 64);
        assert!(a.hash.chars().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(a.hash, b.hash, "a renewal is a new key and certificate");
        // Under the browsers' 14 days, the back-dating included.
        const { assert!(SELF_SIGNED_DAYS * 24 + BACKDATE_HOURS <= 14 * 24) };
        const { assert!(RENEW_EVERY.as_secs() < (SELF_SIGNED_DAYS as u64 - 1) * 24 * 3600) };
    }

    #[tokio::test]
    async fn missing_files_are_named() {
        let source = Source::Files {
            cert: "/nonexistent/cert.pem".into(),
            key: "/nonexistent/key.pem".into(),
        };
        let Err(e) = source.load().await else {
            panic!("no certificate from missing files")
        };
        assert!(e.to_string().contains("/nonexistent/cert.pem"), "{e}");
    }
}
