//! The `--database` setting: a PostgreSQL URL checked, with this server's defaults, and
//! where it points for messages.

use std::time::Duration;

use ::postgres::Config;
use ::postgres::config::{Host, SslMode};

use super::convert::describe;
use crate::store::backend::StoreError;

/// How long connecting may take when the URL does not say (`connect_timeout`).
const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// Checks `url` (a `postgres://` URL or a `key=value` string) and answers its settings and
/// where it points, for messages (never the password).
pub fn parse(url: &str) -> Result<(Config, String), StoreError> {
    if let Some((scheme, _)) = url.split_once("://")
        && scheme != "postgres"
        && scheme != "postgresql"
    {
        return Err(StoreError::DatabaseUrl(format!(
            "{scheme}:// is not a PostgreSQL URL (postgres://user@host/database)"
        )));
    }
    let mut config: Config = url
        .parse()
        .map_err(|e| StoreError::DatabaseUrl(describe(&e)))?;
    if config.get_ssl_mode() == SslMode::Require {
        return Err(StoreError::DatabaseUrl(
            "sslmode=require: this server speaks to PostgreSQL without TLS".into(),
        ));
    }
    if config.get_connect_timeout().is_none() {
        config.connect_timeout(CONNECT_TIMEOUT);
    }
    if config.get_application_name().is_none() {
        config.application_name("lasertag");
    }
    // Notices ("relation already exists, skipping") are the migrations' business only.
    config.notice_callback(|n| tracing::debug!("PostgreSQL: {}", n.message()));
    let ports = config.get_ports();
    let hosts: Vec<String> = config
        .get_hosts()
        .iter()
        .enumerate()
        .map(|(i, h)| match h {
            Host::Tcp(name) => {
                let port = ports.get(i).or(ports.first()).copied().unwrap_or(5432);
                format!("{name}:{port}")
            }
            Host::Unix(path) => path.display().to_string(),
        })
        .collect();
    let target = format!(
        "{}/{}",
        if hosts.is_empty() {
            "the default host".to_string()
        } else {
            hosts.join(",")
        },
        config.get_dbname().or(config.get_user()).unwrap_or("")
    );
    Ok((config, target))
}
