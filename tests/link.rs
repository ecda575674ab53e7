//! The link emulator (tests/common/link.rs) itself: a server inside its namespace answers a
//! client outside through the link, a round trip later; a link that drops everything lets
//! nothing through; and what it made is gone once it is dropped.
//!
//! Needs root, `ip` and nftables (tests/run.sh installs nftables).

#[path = "common/link.rs"]
#[allow(dead_code)]
mod link;

use std::time::{Duration, Instant};

use link::{Link, Shape};

/// A TCP echo server inside `link`, on port 7000 of its address.
fn echo_inside(link: &Link) {
    let ip = link.server_ip;
    link.run_inside(move || {
        let listener = std::net::TcpListener::bind((ip, 7000)).expect("binds inside");
        for stream in listener.incoming().flatten() {
            std::thread::spawn(move || {
                let mut stream = stream;
                let _ = std::io::copy(&mut stream.try_clone().expect("clone"), &mut stream);
            });
        }
    })
    .expect("a thread inside");
    std::thread::sleep(Duration::from_millis(200));
}

fn round_trip(link: &Link) -> std::io::Result<Duration> {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect_timeout(
        &(link.server_ip, 7000).into(),
        Duration::from_secs(2),
    )?;
    s.set_read_timeout(Some(Duration::from_secs(2)))?;
    let t = Instant::now();
    s.write_all(b"ping")?;
    let mut buf = [0u8; 4];
    s.read_exact(&mut buf)?;
    assert_eq!(&buf, b"ping");
    Ok(t.elapsed())
}

#[test]
fn a_server_inside_answers_through_the_link_a_round_trip_later() {
    let link = Link::start(Shape {
        rtt: Duration::from_millis(100),
        loss: 0.0,
        seed: 1,
    })
    .expect("the link starts (root, ip, nft)");
    echo_inside(&link);
    let rtt = round_trip(&link).expect("an answer through the link");
    assert!(rtt >= Duration::from_millis(100), "{rtt:?}");
    let name = format!(" {}:", link.client_tun);
    drop(link);
    let links = std::process::Command::new("ip")
        .args(["-o", "link"])
        .output()
        .expect("ip link");
    let links = String::from_utf8_lossy(&links.stdout);
    assert!(!links.contains(&name), "the link's device is gone: {links}");
}

#[test]
fn a_link_that_drops_everything_lets_nothing_through() {
    let link = Link::start(Shape {
        rtt: Duration::from_millis(10),
        loss: 1.0,
        seed: 2,
    })
    .expect("the link starts (root, ip, nft)");
    echo_inside(&link);
    assert!(round_trip(&link).is_err());
}
