//! `--serve PORT`: the page over HTTP on 127.0.0.1 only, for a browser on
//! another machine that reaches it through ssh port forwarding
//! (`ssh -L PORT:127.0.0.1:PORT HOST`). Loopback keeps the run off the
//! network; the page is one file, so a plain `std::net` loop serves it.

use super::ViewError;
use std::io::{Read, Write};
use std::net::{Ipv4Addr, TcpListener, TcpStream};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

/// A request head larger than this is not a browser asking for the page.
const MAX_REQUEST_HEAD: usize = 16 * 1024;

/// Serves `page` at `/` until the process is stopped. Port 0 takes a free
/// port; the address is printed on stdout either way.
pub fn serve(page: &Path, port: u16) -> Result<(), ViewError> {
    let body = std::fs::read(page)
        .map_err(|e| ViewError::Io(format!("cannot read {}: {e}", page.display())))?;
    let body = Arc::new(body);
    let listener = TcpListener::bind((Ipv4Addr::LOCALHOST, port))
        .map_err(|e| ViewError::Io(format!("cannot listen on 127.0.0.1:{port}: {e}")))?;
    let port = listener
        .local_addr()
        .map_err(|e| ViewError::Io(e.to_string()))?
        .port();
    println!(
        "serving at http://127.0.0.1:{port}/ (Ctrl-C stops; from another machine: ssh -L {port}:127.0.0.1:{port} THIS_HOST, then open that address there)"
    );
    let _ = std::io::stdout().flush();
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        let body = Arc::clone(&body);
        // One thread a connection: a browser's idle second connection must
        // not hold up the one that asks for the page.
        std::thread::spawn(move || {
            let _ = answer(stream, &body);
        });
    }
    Ok(())
}

/// Reads one request head and answers it, then closes the connection.
fn answer(mut stream: TcpStream, page: &[u8]) -> std::io::Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(10)))?;
    let mut head = Vec::new();
    let mut buf = [0u8; 2048];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
        let n = stream.read(&mut buf)?;
        if n == 0 || head.len() + n > MAX_REQUEST_HEAD {
            return Ok(());
        }
        head.extend_from_slice(&buf[..n]);
    }
    let request_line = String::from_utf8_lossy(&head);
    let mut words = request_line.split_whitespace();
    let (method, target) = (words.next().unwrap_or(""), words.next().unwrap_or(""));
    let path = target.split('?').next().unwrap_or("");
    let (status, content_type, body): (&str, &str, &[u8]) = match (method, path) {
        ("GET" | "HEAD", "/" | "/replay.html") => ("200 OK", "text/html; charset=utf-8", page),
        ("GET" | "HEAD", _) => (
            "404 Not Found",
            "text/plain; charset=utf-8",
            b"not found: the replay is at /\n",
        ),
        _ => (
            "405 Method Not Allowed",
            "text/plain; charset=utf-8",
            b"only GET\n",
        ),
    };
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\n\
         Cache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    if method != "HEAD" {
        stream.write_all(body)?;
    }
    stream.flush()
}
