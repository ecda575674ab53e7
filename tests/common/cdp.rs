//! Headless Chromium driven over the DevTools protocol: just enough of it for the browser
//! tests (navigate, evaluate JavaScript, press keys, take a screenshot), over the WebSocket
//! client the other tests use, so no browser-automation crate is needed.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio_tungstenite::tungstenite::Message;

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

pub struct Browser {
    child: Child,
    socket: Socket,
    next_id: u64,
    profile: PathBuf,
}

/// The Chromium binary: `$LASERTAG_CHROMIUM`, else `chromium` (Debian's package).
fn chromium() -> PathBuf {
    if let Ok(p) = std::env::var("LASERTAG_CHROMIUM") {
        return PathBuf::from(p);
    }
    for p in ["/usr/bin/chromium", "/usr/bin/chromium-browser"] {
        if Path::new(p).exists() {
            return PathBuf::from(p);
        }
    }
    panic!(
        "Chromium is not installed: run `bash tests/run.sh` (it installs Debian's chromium) \
         or set LASERTAG_CHROMIUM"
    );
}

impl Browser {
    /// Starts headless Chromium with a fresh profile in a temporary directory.
    pub async fn launch() -> Browser {
        Browser::launch_with(&[]).await
    }

    /// [`Browser::launch`] with `extra` flags on Chromium's command line.
    pub async fn launch_with(extra: &[String]) -> Browser {
        let profile = std::env::temp_dir().join(format!(
            "lasertag-chromium-{}-{}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos())
        ));
        let mut child = Command::new(chromium())
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--disable-component-update",
                "--no-first-run",
                "--disable-quic",
                "--disable-sync",
                "--mute-audio",
                "--hide-scrollbars",
                "--window-size=1280,800",
                "--remote-debugging-port=0",
                "--remote-allow-origins=*",
            ])
            .args(extra)
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg("about:blank")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("Chromium starts");
        // Chromium prints "DevTools listening on ws://127.0.0.1:PORT/devtools/browser/…".
        let stderr = child.stderr.take().expect("stderr");
        let stderr = tokio::process::ChildStderr::from_std(stderr).expect("async stderr");
        let mut lines = BufReader::new(stderr).lines();
        let port = tokio::time::timeout(Duration::from_secs(30), async {
            while let Ok(Some(line)) = lines.next_line().await {
                if let Some(rest) = line.split("ws://127.0.0.1:").nth(1) {
                    return rest.split('/').next().and_then(|p| p.parse::<u16>().ok());
                }
            }
            None
        })
        .await
        .ok()
        .flatten()
        .expect("Chromium announces its DevTools port");
        // Keep draining stderr so Chromium never blocks on a full pipe.
        tokio::spawn(async move { while let Ok(Some(_)) = lines.next_line().await {} });
        let targets: Value = reqwest::get(format!("http://127.0.0.1:{port}/json/list"))
            .await
            .expect("DevTools targets")
            .json()
            .await
            .expect("targets JSON");
        let page = targets
            .as_array()
            .and_then(|t| t.iter().find(|t| t["type"] == "page"))
            .expect("a page target");
        let url = page["webSocketDebuggerUrl"].as_str().expect("page socket");
        let (socket, _) = tokio_tungstenite::connect_async(url)
            .await
            .expect("DevTools socket");
        let mut b = Browser {
            child,
            socket,
            next_id: 0,
            profile,
        };
        b.call("Page.enable", json!({})).await;
        b.call("Runtime.enable", json!({})).await;
        b
    }

    /// Sends one DevTools command and returns its result (events are skipped).
    pub async fn call(&mut self, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let msg = json!({"id": id, "method": method, "params": params});
        self.socket
            .send(Message::Text(msg.to_string().into()))
            .await
            .expect("DevTools send");
        loop {
            let m = tokio::time::timeout(Duration::from_secs(30), self.socket.next())
                .await
                .unwrap_or_else(|_| panic!("{method}: no answer in 30 s"))
                .expect("DevTools socket open")
                .expect("DevTools message");
            let Message::Text(t) = m else { continue };
            let v: Value = serde_json::from_str(t.as_str()).expect("DevTools JSON");
            if v["id"] == id {
                if let Some(e) = v.get("error") {
                    panic!("{method}: {e}");
                }
                return v["result"].clone();
            }
        }
    }

    pub async fn navigate(&mut self, url: &str) {
        self.call("Page.navigate", json!({"url": url})).await;
    }

    /// Evaluates `expr` in the page (awaiting a promise) and returns its value.
    pub async fn eval(&mut self, expr: &str) -> Value {
        let r = self
            .call(
                "Runtime.evaluate",
                json!({"expression": expr, "awaitPromise": true, "returnByValue": true}),
            )
            .await;
        if let Some(e) = r.get("exceptionDetails") {
            panic!("{expr}: {e}");
        }
        r["result"]["value"].clone()
    }

    /// Waits until `expr` is truthy in the page (every 100 ms, at most `secs` seconds).
    pub async fn wait_for(&mut self, expr: &str, secs: u64) -> Value {
        let deadline = Instant::now() + Duration::from_secs(secs);
        let guarded =
            format!("(() => {{ try {{ return {expr}; }} catch (e) {{ return null; }} }})()");
        loop {
            let v = self.eval(&guarded).await;
            let truthy =
                !matches!(&v, Value::Null | Value::Bool(false)) && v != json!(0) && v != json!("");
            if truthy {
                return v;
            }
            if Instant::now() > deadline {
                let state = self
                    .eval("JSON.stringify({...window.__lasertag, feed: (window.__lasertag||{}).feed})")
                    .await;
                panic!("timed out after {secs} s waiting for {expr}; page state: {state}");
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// Presses (`down`) or releases a key, as a person's keyboard would.
    pub async fn key(&mut self, code: &str, down: bool) {
        let (key, vk) = match code {
            "Space" => (" ".to_string(), 32),
            "ArrowUp" => ("ArrowUp".to_string(), 38),
            "ArrowLeft" => ("ArrowLeft".to_string(), 37),
            c if c.starts_with("Key") => {
                let ch = c[3..].to_ascii_lowercase();
                let vk = ch.as_bytes()[0].to_ascii_uppercase() as i64;
                (ch, vk)
            }
            other => panic!("no key {other}"),
        };
        let kind = if down { "keyDown" } else { "keyUp" };
        self.call(
            "Input.dispatchKeyEvent",
            json!({"type": kind, "code": code, "key": key, "windowsVirtualKeyCode": vk}),
        )
        .await;
    }

    pub async fn tap(&mut self, code: &str, hold: Duration) {
        self.key(code, true).await;
        tokio::time::sleep(hold).await;
        self.key(code, false).await;
    }

    /// A phone's screen, `width` × `height` CSS pixels at twice the density.
    pub async fn screen(&mut self, width: u32, height: u32) {
        self.call(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": width, "height": height, "deviceScaleFactor": 2, "mobile": true}),
        )
        .await;
    }

    /// A phone held upright (390 × 844) with a touch screen.
    pub async fn phone(&mut self) {
        self.screen(390, 844).await;
        self.call(
            "Emulation.setTouchEmulationEnabled",
            json!({"enabled": true, "maxTouchPoints": 5}),
        )
        .await;
    }

    /// A PNG of the page.
    /// Saves a screenshot as `name` in `LASERTAG_SCREENSHOTS` when that is set (how the
    /// pictures in docs/screenshots are taken); otherwise does nothing.
    pub async fn save(&mut self, name: &str) {
        if let Ok(dir) = std::env::var("LASERTAG_SCREENSHOTS") {
            let png = self.screenshot().await;
            std::fs::write(std::path::Path::new(&dir).join(name), png).expect("screenshot saved");
        }
    }

    pub async fn screenshot(&mut self) -> Vec<u8> {
        let r = self
            .call("Page.captureScreenshot", json!({"format": "png"}))
            .await;
        base64_decode(r["data"].as_str().expect("screenshot data"))
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.profile);
    }
}

fn base64_decode(s: &str) -> Vec<u8> {
    let val = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0);
    for v in s.bytes().filter_map(val) {
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    out
}
