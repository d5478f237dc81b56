//! Each front end's wording of a refused argument. The catalogue names the argument as
//! the command line takes it (`<IDS>`, `--rate-hz`, `--offset / --amplitude`); a front
//! end whose users write requests as keyword arguments (Python) names the same argument
//! as they write it (`ids=`, `rate_hz=`): [`Wording::Python`], a refusal for want of
//! confirmation says `confirm=True`, and one of the pre-flight `preflight=False`. Only
//! those names change; the value, the reason and the kind stay the library's.

use crate::catalogue::bounds::CONFIRM_HOW;
use crate::ops::OpError;
use crate::ops::preflight::ANYWAY;

/// How a front end names the arguments of a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wording {
    /// The command line's: `<IDS>`, `--rate-hz` (the catalogue's own).
    Cli,
    /// Python's keyword arguments: `ids=`, `rate_hz=` (`from_=` for `--from`).
    Python,
}

/// Python's keywords that a request field shares: given with a trailing `_`.
const PY_KEYWORDS: &[&str] = &[
    "and", "as", "assert", "async", "await", "break", "class", "continue", "def", "del", "elif",
    "else", "except", "finally", "for", "from", "global", "if", "import", "in", "is", "lambda",
    "nonlocal", "not", "or", "pass", "raise", "return", "try", "while", "with", "yield",
];

/// The request field an argument of the command line stands for (`<NEW_ID>`: `new_id`,
/// `--rate-hz`: `rate_hz`), `None` for a word that is not an argument.
fn field_of(token: &str) -> Option<String> {
    let name = if let Some(inner) = token.strip_prefix('<').and_then(|t| t.strip_suffix('>')) {
        inner.to_ascii_lowercase()
    } else if let Some(long) = token.strip_prefix("--") {
        long.to_owned()
    } else {
        return None;
    };
    if name.is_empty()
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return None;
    }
    let mut field = name.replace('-', "_");
    if PY_KEYWORDS.contains(&field.as_str()) {
        field.push('_');
    }
    Some(field)
}

impl Wording {
    /// The name of the argument `option` (as the catalogue gives it) in this wording:
    /// for Python each `<ARG>` and `--arg` becomes `arg=`, the words between them kept
    /// (`--offset / --amplitude`: `offset= / amplitude=`; `--end-board ADDR=VALUE`:
    /// `end_board= ADDR=VALUE`).
    pub fn option(self, option: &str) -> String {
        match self {
            Self::Cli => option.to_owned(),
            Self::Python => option
                .split(' ')
                .map(|t| field_of(t).map_or_else(|| t.to_owned(), |f| format!("{f}=")))
                .collect::<Vec<_>>()
                .join(" "),
        }
    }

    /// The message of `e` in this wording: a refused argument is named as this front
    /// end's users write it (for Python one argument reads `ids=0-300: ...`); every other
    /// error's message is the library's.
    pub fn message(self, e: &OpError) -> String {
        match (self, e) {
            (
                Self::Python,
                OpError::Invalid {
                    option,
                    value,
                    reason,
                },
            ) => {
                let named = self.option(option);
                // One argument: `name=value`, as it was written.
                if !named.contains(' ') && named.ends_with('=') && named != *option {
                    format!("{named}{value}: {reason}; nothing was sent")
                } else {
                    format!("{named} {value}: {reason}; nothing was sent")
                }
            }
            // How to confirm, as a Python caller does it.
            (Self::Python, OpError::Refused(text)) if text.ends_with(CONFIRM_HOW) => {
                let what = &text[..text.len() - CONFIRM_HOW.len()];
                format!("{what}Confirm with confirm=True; nothing was sent")
            }
            // How to run it anyway, as a Python caller does it.
            (Self::Python, OpError::Preflight(_)) => e
                .to_string()
                .replace(ANYWAY, "(preflight=False runs it anyway)"),
            _ => e.to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn python_is_told_to_confirm_with_its_keyword_argument() {
        let e = crate::catalogue::bounds::refused("This writes the EEPROM.");
        assert_eq!(
            Wording::Python.message(&e),
            "This writes the EEPROM. Confirm with confirm=True; nothing was sent"
        );
        assert_eq!(
            Wording::Cli.message(&e),
            "This writes the EEPROM. Confirm with `confirm: true` (the CLI's --yes); nothing \
             was sent"
        );
    }

    #[test]
    fn python_is_told_to_run_past_the_preflight_with_its_keyword_argument() {
        let e = OpError::Preflight(Box::new(crate::ops::preflight::Refusal {
            frame: 5,
            at_s: 0.1,
            joint: "j1".into(),
            reason: "lagged".into(),
        }));
        assert_eq!(
            Wording::Python.message(&e),
            "pre-flight on the simulator: frame 5 at 0.100 s: j1: lagged; nothing was sent \
             (preflight=False runs it anyway)"
        );
        assert!(
            Wording::Cli
                .message(&e)
                .ends_with("(--no-preflight runs it anyway)")
        );
    }

    #[test]
    fn python_names_the_keyword_argument_where_the_cli_names_its_option() {
        let e = OpError::invalid("<IDS>", "0-300", "servo ID 300 is out of range 0..=30");
        assert_eq!(
            Wording::Python.message(&e),
            "ids=0-300: servo ID 300 is out of range 0..=30; nothing was sent"
        );
        assert_eq!(Wording::Cli.message(&e), e.to_string());
        let e = OpError::invalid("--max-speed", -3, "out of range 0.1..=180");
        assert_eq!(
            Wording::Python.message(&e),
            "max_speed=-3: out of range 0.1..=180; nothing was sent"
        );
        let e = OpError::invalid("--offset / --amplitude", "0 / 500", "reach 500 deg");
        assert_eq!(
            Wording::Python.message(&e),
            "offset= / amplitude= 0 / 500: reach 500 deg; nothing was sent"
        );
        assert_eq!(Wording::Python.option("--from"), "from_=");
        assert_eq!(Wording::Python.option("<NEW_ID>"), "new_id=");
        assert_eq!(
            Wording::Python.option("--end-board ADDR=VALUE"),
            "end_board= ADDR=VALUE"
        );
    }

    #[test]
    fn a_name_that_is_no_argument_is_kept() {
        // The parser's `request JSON: ...` and a field already named as the request does.
        let e = OpError::invalid("request", "JSON", "missing field `ids`");
        assert_eq!(Wording::Python.message(&e), e.to_string());
        assert_eq!(Wording::Python.option("position"), "position");
        assert_eq!(Wording::Python.option("--"), "--");
        let other = OpError::Refused("needs confirm".into());
        assert_eq!(Wording::Python.message(&other), "needs confirm");
    }
}
