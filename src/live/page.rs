//! The live page: `viewer/src/live.html` with the scene's name and the
//! committed bundle `viewer/dist/live.js` (three.js and `viewer/src/live.js`,
//! built by `viewer/build.mjs`) written into it. Both are compiled into the
//! binary; the page gets everything else over its WebSocket.

use crate::view::page::{fill_template, html_escape};

const TEMPLATE: &str = include_str!("../../viewer/src/live.html");
const BUNDLE: &str = include_str!("../../viewer/dist/live.js");

/// The whole page for the scene `scene_name`.
pub fn html(scene_name: &str) -> String {
    let title = html_escape(scene_name);
    fill_template(
        TEMPLATE,
        "viewer/src/live.html",
        &[("TITLE", &title), ("SCRIPT", BUNDLE)],
    )
}

#[cfg(test)]
mod tests {
    /// The bundle is inlined as it is, so it must not end its own element.
    #[test]
    fn the_bundle_can_be_inlined_in_a_script_element() {
        let lower = super::BUNDLE.to_lowercase();
        assert!(!lower.contains("</script") && !lower.contains("<!--"));
        let page = super::html("a <b> & c");
        assert!(page.contains("a &lt;b&gt; &amp; c · rigidsim live"));
    }
}
