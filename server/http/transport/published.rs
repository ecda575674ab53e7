//! Where WebTransport is served, once [`super::start`] runs: what `GET /api/transport`
//! tells a page (the port, and the hash of a certificate the page must pin).

use std::sync::RwLock;

/// Where WebTransport is served, once it is: what `GET /api/transport` says.
#[derive(Debug, Default)]
pub struct Published(RwLock<Option<Info>>);

#[derive(Debug, Clone)]
pub(super) struct Info {
    pub(super) port: u16,
    /// The certificate's hash when pages must pin it (the server's own).
    pub(super) hash: Option<String>,
}

impl Published {
    pub(super) fn set(&self, info: Info) {
        if let Ok(mut at) = self.0.write() {
            *at = Some(info);
        }
    }

    pub(super) fn get(&self) -> Option<Info> {
        self.0.read().ok().and_then(|at| at.clone())
    }
}
