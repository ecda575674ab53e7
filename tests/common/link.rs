//! A link emulator for the tests and measurement programs: delay and loss, both ways, for TCP
//! and UDP alike, without ending TCP (its own retransmissions happen end to end, as on a real
//! link). These machines have no netem, so the link is made of two TUN devices and a
//! forwarder between them:
//!
//! ```text
//! this namespace: client ──► tun lt<pid>c 198.18.<n>.1 ─┐
//!                                                        forwarder: holds each packet the
//!                                                        one-way delay, drops a share
//! a namespace of its own: server ◄── tun lt<pid>s 198.18.<n>.2 ─┘
//! ```
//!
//! The server's end lives in a network namespace the link makes ([`Link::run_inside`] runs a
//! server there: its threads, and every socket they bind, are in it), held only by this
//! process's file descriptors: it vanishes with the process, killed or not, and so do the TUN
//! devices (a TUN that is not persistent goes with its last descriptor). A guard table in
//! nftables, owned by an `nft -i` child that ends when this process does, drops any packet for
//! the link's addresses leaving by another device. Addresses come from 198.18.0.0/15, the
//! range set aside for benchmarks. Needs root and `ip` and `nft`.

use std::fs::File;
use std::io::{self, Read, Write};
use std::net::Ipv4Addr;
use std::os::fd::{AsRawFd, FromRawFd};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::io::unix::AsyncFd;

/// Links made by this process so far (each takes the next /30 of the range).
static MADE: AtomicU32 = AtomicU32::new(0);

/// What the link does to each packet, each way.
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    /// The round trip it adds (half each way).
    pub rtt: Duration,
    /// The share of packets it drops, each way (0..1).
    pub loss: f64,
    pub seed: u64,
}

pub struct Link {
    /// The server's address, inside the link's namespace.
    pub server_ip: Ipv4Addr,
    /// The name of the TUN device on this side.
    pub client_tun: String,
    namespace: File,
    _tuns: Vec<Arc<AsyncFd<File>>>,
    guard: Child,
    forwarder: Option<std::thread::JoinHandle<()>>,
    stop: Arc<std::sync::atomic::AtomicBool>,
}

/// Makes the TUN device node where a container left it out (`/dev/net/tun`, character
/// device 10:200, as the kernel's documentation gives it); a no-op where it exists.
fn ensure_tun_node() {
    let path = std::path::Path::new("/dev/net/tun");
    if path.exists() {
        return;
    }
    let _ = std::fs::create_dir_all("/dev/net");
    // SAFETY: mknod with a constant path and device number.
    unsafe {
        libc::mknod(
            c"/dev/net/tun".as_ptr(),
            libc::S_IFCHR | 0o666,
            libc::makedev(10, 200),
        );
    }
}

fn open_tun(name: &str) -> io::Result<File> {
    ensure_tun_node();
    // SAFETY: plain system calls on a descriptor this function owns; `ifreq` is zeroed and
    // its name bounded by the array's length (interface names are at most 15 bytes).
    unsafe {
        let fd = libc::open(
            c"/dev/net/tun".as_ptr(),
            libc::O_RDWR | libc::O_NONBLOCK | libc::O_CLOEXEC,
        );
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        let file = File::from_raw_fd(fd);
        let mut ifr: libc::ifreq = std::mem::zeroed();
        for (d, s) in ifr.ifr_name.iter_mut().zip(name.bytes().take(15)) {
            *d = s as libc::c_char;
        }
        ifr.ifr_ifru.ifru_flags =
            (libc::IFF_TUN | libc::IFF_NO_PI | libc::IFF_TUN_EXCL) as libc::c_short;
        if libc::ioctl(
            file.as_raw_fd(),
            libc::TUNSETIFF,
            &ifr as *const libc::ifreq,
        ) < 0
        {
            return Err(io::Error::last_os_error());
        }
        Ok(file)
    }
}

/// Runs `ip` with `args` in the calling thread's namespace.
fn ip(args: &[&str]) -> io::Result<()> {
    let status = Command::new("ip")
        .args(args)
        .stdout(Stdio::null())
        .status()?;
    if status.success() {
        Ok(())
    } else {
        Err(io::Error::other(format!("ip {}: {status}", args.join(" "))))
    }
}

/// Brings up TUN `name` with `local` and its peer `peer`, in the calling thread's namespace.
fn bring_up(name: &str, local: Ipv4Addr, peer: Ipv4Addr) -> io::Result<File> {
    let tun = open_tun(name)?;
    // No IPv6 link-local address, so no neighbour discovery chatter on the link.
    ip(&["link", "set", "dev", name, "addrgenmode", "none"])?;
    ip(&["link", "set", "dev", name, "mtu", "1500"])?;
    ip(&[
        "addr",
        "add",
        &local.to_string(),
        "peer",
        &peer.to_string(),
        "dev",
        name,
    ])?;
    ip(&["link", "set", "dev", name, "up"])?;
    Ok(tun)
}

impl Link {
    /// Makes a link shaped as `shape`: the namespace, both TUNs, the guard and the forwarder.
    pub fn start(shape: Shape) -> io::Result<Link> {
        let n = MADE.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id();
        let base = u32::from(Ipv4Addr::new(198, 18, 0, 0)) + 4 * (pid % 4_000 * 8 + n % 8);
        let client_ip = Ipv4Addr::from(base + 1);
        let server_ip = Ipv4Addr::from(base + 2);
        let (client_tun, server_tun) = (format!("lt{pid}c{n}"), format!("lt{pid}s{n}"));
        let guard = guard(&format!("lt_link_{pid}_{n}"), base, &client_tun)?;
        // The server's end: a namespace of its own, made on a thread that goes with it.
        let (namespace, server_file) = std::thread::scope(|s| {
            s.spawn(|| -> io::Result<(File, File)> {
                // SAFETY: unshare affects this thread only.
                if unsafe { libc::unshare(libc::CLONE_NEWNET) } != 0 {
                    return Err(io::Error::last_os_error());
                }
                let ns = File::open("/proc/thread-self/ns/net")?;
                ip(&["link", "set", "lo", "up"])?;
                let tun = bring_up(&server_tun, server_ip, client_ip)?;
                Ok((ns, tun))
            })
            .join()
            .map_err(|_| io::Error::other("the namespace's thread panicked"))?
        })?;
        let client_file = bring_up(&client_tun, client_ip, server_ip)?;
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (tx, rx) = std::sync::mpsc::channel();
        let stopping = stop.clone();
        let forwarder = std::thread::Builder::new()
            .name("link-forwarder".into())
            .spawn(move || {
                let rt = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                    .expect("the forwarder's runtime");
                rt.block_on(async move {
                    // SAFETY: each `File` owns its descriptor and is moved in: it stays open
                    // and the same for the `AsyncFd`'s life.
                    let register = |f: File| unsafe { AsyncFd::register(f) }.ok();
                    let c = Arc::new(register(client_file).expect("client TUN"));
                    let s = Arc::new(register(server_file).expect("server TUN"));
                    let _ = tx.send(vec![c.clone(), s.clone()]);
                    let one_way = shape.rtt / 2;
                    let a = direction(c.clone(), s.clone(), one_way, shape.loss, shape.seed);
                    let b = direction(s, c, one_way, shape.loss, shape.seed ^ 0x9e37_79b9);
                    let watch = async {
                        while !stopping.load(Ordering::Relaxed) {
                            tokio::time::sleep(Duration::from_millis(50)).await;
                        }
                    };
                    tokio::select! {
                        () = a => {}
                        () = b => {}
                        () = watch => {}
                    }
                });
            })?;
        let tuns = rx
            .recv_timeout(Duration::from_secs(5))
            .map_err(|_| io::Error::other("the forwarder did not start"))?;
        Ok(Link {
            server_ip,
            client_tun,
            namespace,
            _tuns: tuns,
            guard,
            forwarder: Some(forwarder),
            stop,
        })
    }

    /// Runs `f` on a new thread inside the link's namespace and returns what it returns:
    /// threads it starts, and sockets they bind, stay there.
    pub fn run_inside<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> io::Result<std::thread::JoinHandle<T>> {
        let ns = self.namespace.try_clone()?;
        std::thread::Builder::new()
            .name("link-inside".into())
            .spawn(move || {
                // SAFETY: setns on this thread only, with a descriptor of a network namespace.
                let entered = unsafe { libc::setns(ns.as_raw_fd(), libc::CLONE_NEWNET) };
                assert_eq!(entered, 0, "setns: {}", io::Error::last_os_error());
                f()
            })
    }
}

impl Link {
    /// Runs `start` on a tokio runtime of its own (2 workers) inside the link's namespace,
    /// kept running for the rest of the process (a server started there goes on serving);
    /// what `start` returns.
    pub async fn serve_inside<T, F, Fut>(&self, start: F) -> io::Result<T>
    where
        T: Send + 'static,
        F: FnOnce() -> Fut + Send + 'static,
        Fut: std::future::Future<Output = T>,
    {
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.run_inside(move || {
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .expect("a runtime inside the link");
            rt.block_on(async move {
                let _ = tx.send(start().await);
                std::future::pending::<()>().await
            })
        })?;
        rx.await
            .map_err(|_| io::Error::other("the thread inside the link ended"))
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(f) = self.forwarder.take() {
            let _ = f.join();
        }
        // Its stdin closed, `nft -i` ends, and its table with it.
        drop(self.guard.stdin.take());
        let _ = self.guard.wait();
    }
}

/// An nftables table owned by an `nft -i` child (`flags owner`: gone when the child is): any
/// packet for the link's /30 leaving by a device other than `lo` and the client's TUN is
/// dropped.
fn guard(table: &str, base: u32, client_tun: &str) -> io::Result<Child> {
    let net = Ipv4Addr::from(base);
    let mut child = Command::new("nft")
        .arg("-i")
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| io::Error::other(format!("nft: {e} (install nftables)")))?;
    let script = format!(
        "add table inet {table} {{ flags owner; }}\n\
         add chain inet {table} out_guard {{ type filter hook output priority 0; policy accept; }}\n\
         add rule inet {table} out_guard ip daddr {net}/30 oifname != {{ \"lo\", \"{client_tun}\" }} drop\n"
    );
    let stdin = child
        .stdin
        .as_mut()
        .ok_or_else(|| io::Error::other("nft's stdin"))?;
    stdin.write_all(script.as_bytes())?;
    stdin.flush()?;
    Ok(child)
}

async fn recv(tun: &AsyncFd<File>, buf: &mut [u8]) -> io::Result<usize> {
    loop {
        let mut ready = tun.readable().await?;
        if let Ok(r) = ready.try_io(|f| f.get_ref().read(buf)) {
            return r;
        }
    }
}

async fn send(tun: &AsyncFd<File>, packet: &[u8]) -> io::Result<()> {
    loop {
        let mut ready = tun.writable().await?;
        if let Ok(r) = ready.try_io(|f| f.get_ref().write(packet)) {
            return r.map(drop);
        }
    }
}

/// One way of the link: every IPv4 packet read from `from` is dropped with probability
/// `loss`, or written to `to` `one_way` later, in order.
async fn direction(
    from: Arc<AsyncFd<File>>,
    to: Arc<AsyncFd<File>>,
    one_way: Duration,
    loss: f64,
    seed: u64,
) {
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<(tokio::time::Instant, Vec<u8>)>();
    let reader = async move {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut buf = vec![0u8; 65536];
        while let Ok(n) = recv(&from, &mut buf).await {
            if n == 0 || buf[0] >> 4 != 4 || rng.random_bool(loss) {
                continue;
            }
            let at = tokio::time::Instant::now() + one_way;
            if tx.send((at, buf[..n].to_vec())).is_err() {
                break;
            }
        }
    };
    let writer = async move {
        while let Some((at, packet)) = rx.recv().await {
            tokio::time::sleep_until(at).await;
            let _ = send(&to, &packet).await;
        }
    };
    tokio::join!(reader, writer);
}
