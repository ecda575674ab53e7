//! HTTPS on the server's TCP port with the operator's certificate (`--tls-cert`,
//! `--tls-key`): the page, the API and the WebSockets (`wss://`) over TLS, as browsers need
//! for WebTransport on any host but localhost (a page must be a secure context). The same
//! certificate serves WebTransport in UDP (`transport::certificate`). Without one the server
//! speaks plain HTTP: its own certificate is for pinning by hash, which only WebTransport
//! offers, not for pages.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use tokio_rustls::TlsAcceptor;

#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    #[error("reading {path}: {error}")]
    Read { path: PathBuf, error: String },
    #[error("{path} holds no PEM certificate")]
    NoCertificate { path: PathBuf },
    #[error("the certificate {cert} and key {key} do not make a TLS server: {error}")]
    Config {
        cert: PathBuf,
        key: PathBuf,
        error: String,
    },
}

/// The acceptor of HTTPS connections with the certificate chain in `cert` and its private
/// key in `key` (PEM files), speaking HTTP/1.1 inside (what the server speaks over TCP).
pub fn acceptor(cert: &Path, key: &Path) -> Result<TlsAcceptor, TlsError> {
    let read = |path: &Path| {
        std::fs::read(path).map_err(|e| TlsError::Read {
            path: path.to_owned(),
            error: e.to_string(),
        })
    };
    let chain = CertificateDer::pem_slice_iter(&read(cert)?)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| TlsError::Read {
            path: cert.to_owned(),
            error: e.to_string(),
        })?;
    if chain.is_empty() {
        return Err(TlsError::NoCertificate {
            path: cert.to_owned(),
        });
    }
    let secret = PrivateKeyDer::from_pem_slice(&read(key)?).map_err(|e| TlsError::Read {
        path: key.to_owned(),
        error: e.to_string(),
    })?;
    let config_error = |error: String| TlsError::Config {
        cert: cert.to_owned(),
        key: key.to_owned(),
        error,
    };
    // The crate's one provider, ring (see Cargo.toml).
    let mut config = rustls::ServerConfig::builder()
        .with_no_client_auth()
        .with_single_cert(chain, secret)
        .map_err(|e| config_error(e.to_string()))?;
    config.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(TlsAcceptor::from(Arc::new(config)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_or_empty_files_are_named() {
        let dir = std::env::temp_dir().join(format!("lasertag-tls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let empty = dir.join("empty.pem");
        std::fs::write(&empty, "").unwrap();
        let e = acceptor(&dir.join("none.pem"), &empty)
            .err()
            .expect("an error");
        assert!(e.to_string().contains("none.pem"), "{e}");
        let e = acceptor(&empty, &empty).err().expect("an error");
        assert!(e.to_string().contains("no PEM certificate"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
