//! The page: `viewer/src/replay.html` with the header, the base64 data and
//! the committed bundle `viewer/dist/viewer.js` (three.js and the viewer,
//! built by `viewer/build.mjs`) written into it. Both files are compiled
//! into the binary, so `rigidsim view` needs neither npm nor the source tree.

use super::replay_data::ReplayData;
use base64::Engine;

const TEMPLATE: &str = include_str!("../../viewer/src/replay.html");
const BUNDLE: &str = include_str!("../../viewer/dist/viewer.js");

/// Text inside a `<script>` element ends at the first `</script` (and
/// `<!--` changes how it is read): JSON may write `<` only inside strings,
/// where `\u003c` means the same.
fn json_in_script(json: &str) -> String {
    json.replace('<', "\\u003c")
}

pub(crate) fn html_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// `template` (the file `name`, for the panic) with each `{{KEY}}` replaced
/// by `KEY`'s text in `values`. Placeholders are replaced in one pass over
/// the template, so nothing substituted (a scene name, a bundle) is
/// searched for placeholders.
pub(crate) fn fill_template(template: &str, name: &str, values: &[(&str, &str)]) -> String {
    let filled: usize = values.iter().map(|(_, text)| text.len()).sum();
    let mut out = String::with_capacity(template.len() + filled);
    let mut rest = template;
    while let Some(start) = rest.find("{{") {
        let end = start
            + rest[start..]
                .find("}}")
                .expect("template placeholders are closed");
        out.push_str(&rest[..start]);
        let key = &rest[start + 2..end];
        match values.iter().find(|(k, _)| *k == key) {
            Some((_, text)) => out.push_str(text),
            None => panic!("unknown placeholder {key} in {name}"),
        }
        rest = &rest[end + 2..];
    }
    out.push_str(rest);
    out
}

/// The whole page for `scene_name`.
pub fn html(scene_name: &str, data: &ReplayData) -> String {
    let header = serde_json::to_string(&data.header).expect("the header is plain data");
    let base64 = base64::engine::general_purpose::STANDARD.encode(&data.binary);
    fill_template(
        TEMPLATE,
        "viewer/src/replay.html",
        &[
            ("TITLE", &html_escape(scene_name)),
            ("HEADER", &json_in_script(&header)),
            ("DATA", &base64),
            ("SCRIPT", BUNDLE),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bundle is inlined as it is, so it must not end its own element
    /// (`viewer/build.mjs` refuses to write such a bundle, too).
    #[test]
    fn the_bundle_can_be_inlined_in_a_script_element() {
        let lower = BUNDLE.to_ascii_lowercase();
        assert!(!lower.contains("</script"));
        assert!(!lower.contains("<!--"));
    }

    #[test]
    fn json_in_a_script_element_has_no_angle_bracket() {
        let json = serde_json::to_string(&["</script><!--"]).unwrap();
        let safe = json_in_script(&json);
        assert!(!safe.contains('<'));
        let back: Vec<String> = serde_json::from_str(&safe).unwrap();
        assert_eq!(back, ["</script><!--"]);
    }
}
