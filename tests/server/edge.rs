//! The HTTP edge: slow clients cut at the header timeout, connections capped.

use super::*;

#[test]
fn slow_clients_are_cut_at_the_header_timeout_and_connections_are_capped() {
    // Four connections (the cap) that never finish their headers hold every slot: a fifth client
    // waits until the header-read timeout (1 s) closes them, then is served.
    use std::io::{Read, Write};
    let dir = tempdir("edge");
    let srv = start_with(
        &dir,
        false,
        "max_connections = 4\nheader_read_timeout_s = 1.0\n",
    );
    let a = srv.addr.as_str();
    let t0 = Instant::now();
    let (code, _) = call(a, "GET", "/api/v1/healthz", None, None);
    assert_eq!(code, 200);
    let idle = t0.elapsed();
    let mut slow: Vec<std::net::TcpStream> = (0..4)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(a).unwrap();
            s.write_all(b"GET /api/v1/healthz HTTP/1.1\r\nHost: x\r\n")
                .unwrap();
            s
        })
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    let t0 = Instant::now();
    let (code, _) = call(a, "GET", "/api/v1/healthz", None, None);
    let capped = t0.elapsed();
    assert_eq!(code, 200);
    eprintln!("healthz idle {idle:?}; behind four stalled clients {capped:?}");
    assert!(
        capped >= Duration::from_millis(500) && capped < Duration::from_secs(6),
        "the fifth client waits for the stalled ones' timeout, and no longer: {capped:?}"
    );
    // The stalled connections were closed by the server (end of stream, or a reset).
    for s in &mut slow {
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let mut buf = [0u8; 256];
        match s.read(&mut buf) {
            Ok(n) => assert!(
                n == 0 || buf.starts_with(b"HTTP/1.1 408"),
                "{}",
                String::from_utf8_lossy(&buf[..n])
            ),
            Err(e) => assert!(
                !matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ),
                "a stalled connection is still open: {e}"
            ),
        }
    }
    // An idle keep-alive connection, its request answered, is closed after as long.
    let mut kept = std::net::TcpStream::connect(a).unwrap();
    kept.write_all(b"GET /api/v1/healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        .unwrap();
    kept.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut got = Vec::new();
    let t0 = Instant::now();
    let read = kept.read_to_end(&mut got);
    assert!(
        read.is_ok() && got.starts_with(b"HTTP/1.1 200"),
        "{read:?} after {:?}: {}",
        t0.elapsed(),
        String::from_utf8_lossy(&got)
    );
}
