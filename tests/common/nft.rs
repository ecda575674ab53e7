//! Packet loss on loopback for the tests and measurements, from nftables: a table of its own
//! whose input hook drops a share of the UDP (and, if asked, TCP) packets to or from one port,
//! at random (both directions: on loopback every packet passes the input hook). Dropping in the output hook instead makes
//! the sender's `sendmsg` fail (EPERM), which QUIC takes for a dead path. Removed on drop.
//! Needs root and `nft` (tests/run.sh installs nftables).

use std::process::Command;

pub struct Loss {
    table: String,
}

fn nft(script: &str) -> Result<(), String> {
    let out = Command::new("nft")
        .args(["-f", "-"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .and_then(|mut child| {
            use std::io::Write;
            if let Some(mut stdin) = child.stdin.take() {
                stdin.write_all(script.as_bytes())?;
            }
            child.wait_with_output()
        })
        .map_err(|e| format!("nft: {e} (install nftables; tests/run.sh does)"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!("nft: {}", String::from_utf8_lossy(&out.stderr)))
    }
}

impl Loss {
    /// Drops `percent` of the UDP packets to `port` and of those from it; 100 drops all.
    pub fn udp(port: u16, percent: u32) -> Loss {
        Loss::start(port, percent, &["udp"])
    }

    /// Drops `percent` of the UDP and the TCP packets to `port` and from it.
    pub fn udp_and_tcp(port: u16, percent: u32) -> Loss {
        Loss::start(port, percent, &["udp", "tcp"])
    }

    fn start(port: u16, percent: u32, protocols: &[&str]) -> Loss {
        let table = format!("lasertag_loss_{port}");
        let drop = if percent >= 100 {
            "drop".to_string()
        } else {
            format!("numgen random mod 100 < {percent} drop")
        };
        let rules: String = protocols
            .iter()
            .map(|p| format!("  {p} dport {port} {drop}\n  {p} sport {port} {drop}\n"))
            .collect();
        let script = format!(
            "table inet {table} {{\n chain input {{\n  type filter hook input priority 0; policy accept;\n{rules} }}\n}}\n"
        );
        nft(&script).expect("an nftables table for the loss");
        Loss { table }
    }
}

impl Drop for Loss {
    fn drop(&mut self) {
        let _ = nft(&format!("delete table inet {}\n", self.table));
    }
}
