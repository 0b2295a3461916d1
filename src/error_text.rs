//! How the page words an error: the message, then each cause it carries, so that what the
//! libraries kept (a decoder's or the device's own account) reaches the person reading it.

use std::error::Error;

/// `error`'s message followed by its causes, `: `-separated (as `hnet` prints them).
pub fn with_causes(error: &dyn Error) -> String {
    let mut text = error.to_string();
    let mut cause = error.source();
    while let Some(e) = cause {
        let message = e.to_string();
        // A wrapper that repeats its cause's words adds nothing.
        if !text.ends_with(&message) {
            text.push_str(": ");
            text.push_str(&message);
        }
        cause = e.source();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causes_follow_the_message() {
        let err =
            crate::imaging::decode_to_rgb("scan.png", b"\x89PNG\r\n\x1a\n broken", 8).unwrap_err();
        let text = with_causes(&err);
        assert!(text.starts_with("scan.png: cannot be decoded: "), "{text}");
        assert!(text.len() > "scan.png: cannot be decoded: ".len(), "{text}");
    }
}
