//! The server in this process, on 127.0.0.1 and an ephemeral port, without a showcase: what
//! the measurement programs in `examples/` run against (each includes this file by path).

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

/// Serves the maps of `maps` and the page of `web/` with the default settings; the address.
#[allow(dead_code)]
pub async fn start(maps: &Path) -> Result<SocketAddr, String> {
    let maps =
        lasertag::maps::MapStore::load_dir(maps).map_err(|e| format!("loading maps: {e}"))?;
    let registry = lasertag::game::Registry::with_config(maps, lasertag::config::Config::default());
    let app = lasertag::http::app(registry, PathBuf::from("web"))
        .into_make_service_with_connect_info::<SocketAddr>();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .map_err(|e| e.to_string())?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    tokio::spawn(async move { axum::serve(listener, app).await });
    Ok(addr)
}

/// [`start`], with WebTransport on the same port in UDP (its own certificate).
#[allow(dead_code)]
pub async fn start_with_webtransport(maps: &Path) -> Result<SocketAddr, String> {
    start_with_webtransport_on(maps, std::net::Ipv4Addr::LOCALHOST.into()).await
}

/// [`start_with_webtransport`] on address `ip` (a link emulator's, say).
#[allow(dead_code)]
pub async fn start_with_webtransport_on(
    maps: &Path,
    ip: std::net::IpAddr,
) -> Result<SocketAddr, String> {
    let maps =
        lasertag::maps::MapStore::load_dir(maps).map_err(|e| format!("loading maps: {e}"))?;
    let registry = lasertag::game::Registry::with_config(maps, lasertag::config::Config::default());
    let (app, state) = lasertag::http::app_and_state(registry.clone(), PathBuf::from("web"), None);
    let listener = tokio::net::TcpListener::bind((ip, 0))
        .await
        .map_err(|e| e.to_string())?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    let source = lasertag::http::transport::Source::SelfSigned;
    lasertag::http::transport::start(state, addr, source)
        .await
        .map_err(|e| e.to_string())?;
    // The binary's own accept loop (TCP_NODELAY on each connection, its caps), so that a
    // WebSocket over a long link is measured as it is served.
    lasertag::http::raise_open_files_limit();
    let limits = lasertag::http::ConnectionLimits::of(&registry).map_err(|e| e.to_string())?;
    tokio::spawn(lasertag::http::serve(
        listener,
        app,
        limits,
        std::future::pending(),
    ));
    Ok(addr)
}
