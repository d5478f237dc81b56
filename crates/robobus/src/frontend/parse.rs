//! One parser of a request for every front end: JSON text (a studio's body, a bridge's
//! query), a `serde_json::Value` (a field of a studio's WebSocket message) and Python's
//! keyword arguments once turned into a value. Every refusal has one wording: the
//! option `request`, the value `JSON`, serde's reason and what a request is; nothing
//! was sent ([`ErrorKind::BadInput`](crate::ErrorKind::BadInput)).

use serde_json::Value;

use crate::catalogue::Request;
use crate::ops::OpError;

/// The largest request text taken, bytes (a motion program or a keyframe file fits
/// easily).
pub const MAX_REQUEST_BYTES: usize = 4 << 20;

/// What every refusal adds to serde's reason.
const WHAT: &str = "one request object, as the request schema (`robobus schema`) describes";

fn refused(e: &impl std::fmt::Display) -> OpError {
    OpError::invalid("request", "JSON", format!("{e} ({WHAT})"))
}

/// One request from JSON text.
///
/// # Errors
///
/// Bad input: text over [`MAX_REQUEST_BYTES`], bad JSON, an unknown operation or field,
/// a missing or mistyped argument.
pub fn request_text(text: &str) -> Result<Request, OpError> {
    if text.len() > MAX_REQUEST_BYTES {
        return Err(too_long(text.len()));
    }
    serde_json::from_str(text).map_err(|e| refused(&e))
}

/// One request from the bytes of a body: as [`request_text`], and bytes that are not
/// UTF-8 are bad input too.
///
/// # Errors
///
/// As [`request_text`].
pub fn request_bytes(body: &[u8]) -> Result<Request, OpError> {
    if body.len() > MAX_REQUEST_BYTES {
        return Err(too_long(body.len()));
    }
    let text = std::str::from_utf8(body).map_err(|e| refused(&format!("not UTF-8: {e}")))?;
    request_text(text)
}

/// One request from a JSON value (a WebSocket message's `request`, Python's keyword
/// arguments).
///
/// # Errors
///
/// As [`request_text`] (the size is the sender's: a value is already in memory).
pub fn request_value(value: Value) -> Result<Request, OpError> {
    serde_json::from_value(value).map_err(|e| refused(&e))
}

fn too_long(len: usize) -> OpError {
    OpError::invalid(
        "request",
        format!("{len} bytes"),
        format!("at most {MAX_REQUEST_BYTES} bytes"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ErrorKind;

    /// The wording every front end shows for an unknown field.
    const UNKNOWN_FIELD: &str = "request JSON: unknown field `colour`";

    #[test]
    fn text_bytes_and_value_refuse_in_one_wording() {
        let text = r#"{"op": "wck.status", "ids": "0", "colour": "red"}"#;
        let value: Value = serde_json::from_str(text).unwrap();
        let errors = [
            request_text(text).unwrap_err(),
            request_bytes(text.as_bytes()).unwrap_err(),
            request_value(value).unwrap_err(),
        ];
        for e in &errors {
            assert_eq!(e.kind(), ErrorKind::BadInput);
            let m = e.to_string();
            assert!(m.starts_with(UNKNOWN_FIELD), "{m}");
            assert!(m.ends_with(&format!("({WHAT}); nothing was sent")), "{m}");
        }
        // The value carries no line and column; the texts the same ones.
        assert_eq!(errors[0].to_string(), errors[1].to_string());
    }

    #[test]
    fn a_request_parses_the_same_from_text_bytes_and_value() {
        let text = r#"{"op": "whj.move", "joint": 3, "degrees": 10}"#;
        let json = |r: Request| serde_json::to_value(r).unwrap();
        let a = json(request_text(text).unwrap());
        assert_eq!(a["op"], "whj.move");
        assert_eq!(json(request_bytes(text.as_bytes()).unwrap()), a);
        assert_eq!(
            json(request_value(serde_json::from_str(text).unwrap()).unwrap()),
            a
        );
    }

    #[test]
    fn bytes_that_are_not_utf8_or_too_many_are_bad_input() {
        let e = request_bytes(&[b'{', 0xff, b'}']).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput);
        assert!(e.to_string().starts_with("request JSON: not UTF-8"), "{e}");
        let long = " ".repeat(MAX_REQUEST_BYTES + 1);
        let e = request_text(&long).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "request {} bytes: at most {MAX_REQUEST_BYTES} bytes; nothing was sent",
                MAX_REQUEST_BYTES + 1
            )
        );
    }
}
