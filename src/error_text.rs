//! How the page words an error: the message, then each cause it carries, so that what the
//! libraries kept (a decoder's or the device's own account) reaches the person reading it. The
//! wording is [`hnet_units::with_causes`], shared with the WebGPU worker (crates/hnet-gpu).

pub use hnet_units::with_causes;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causes_follow_the_message() {
        let err = crate::imaging::decode_to_rgb(
            "scan.png",
            b"\x89PNG\r\n\x1a\n broken",
            hnet_units::ImageSize::square(8),
        )
        .unwrap_err();
        let text = with_causes(&err);
        assert!(text.starts_with("scan.png: cannot be decoded: "), "{text}");
        assert!(text.len() > "scan.png: cannot be decoded: ".len(), "{text}");
    }
}
