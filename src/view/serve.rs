//! `--serve PORT`: the page over HTTP on 127.0.0.1 only, for a browser on
//! another machine that reaches it through ssh port forwarding
//! (`ssh -L PORT:127.0.0.1:PORT HOST`). Loopback keeps the run off the
//! network. The same HTTP stack as `rigidsim live` (`super::http`).

use super::ViewError;
use std::path::Path;

/// Serves `page` at `/` until the process is stopped. Port 0 takes a free
/// port; the address is printed on stdout either way.
pub fn serve(page: &Path, port: u16) -> Result<(), ViewError> {
    let body = std::fs::read(page)
        .map_err(|e| ViewError::Io(format!("cannot read {}: {e}", page.display())))?;
    super::http::serve_page(body, port)
        .map_err(|e| ViewError::Io(format!("cannot listen on 127.0.0.1:{port}: {e}")))
}
