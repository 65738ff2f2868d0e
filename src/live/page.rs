//! The live page: `viewer/src/live.html` with the scene's name and the
//! committed bundle `viewer/dist/live.js` (three.js and `viewer/src/live.js`,
//! built by `viewer/build.mjs`) written into it. Both are compiled into the
//! binary; the page gets everything else over its WebSocket.

const TEMPLATE: &str = include_str!("../../viewer/src/live.html");
const BUNDLE: &str = include_str!("../../viewer/dist/live.js");

fn html_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The whole page for the scene `scene_name`.
pub fn html(scene_name: &str) -> String {
    // One pass over the template: nothing substituted is searched again.
    let mut out = String::with_capacity(TEMPLATE.len() + BUNDLE.len());
    let mut rest = TEMPLATE;
    while let Some(start) = rest.find("{{") {
        let end = start
            + rest[start..]
                .find("}}")
                .expect("template placeholders are closed");
        out.push_str(&rest[..start]);
        match &rest[start + 2..end] {
            "TITLE" => out.push_str(&html_escape(scene_name)),
            "SCRIPT" => out.push_str(BUNDLE),
            other => panic!("unknown placeholder {other} in viewer/src/live.html"),
        }
        rest = &rest[end + 2..];
    }
    out.push_str(rest);
    out
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
