//! The words each front end gives the library's settings, in one table.
//!
//! The library's errors name a setting by its name (`out`, `force`, `clipped`,
//! `pulse_len`), as [`Error::InvalidParameter`]'s name or, in a message's text, between
//! backticks (`` `force` ``). Each front end renders an error in its own words through
//! [`FrontEnd::render`]: the command line's flags (`--out`, `--force`, `--pulse-len`), the
//! Python package's arguments (`out`, `force=True`, `pulse_len`). A setting not in [`SETTINGS`]
//! is named by the rule of its front end: `--` and the name with hyphens, or the name itself.
//!
//! ```
//! use rdlidar::settings::FrontEnd;
//! use rdlidar::Error;
//!
//! let e = Error::InvalidParameter {
//!     name: "out",
//!     reason: "the folder is not empty: `force` replaces its files".into(),
//! };
//! assert_eq!(
//!     FrontEnd::CommandLine.render(&e),
//!     "--out: the folder is not empty: --force replaces its files"
//! );
//! assert_eq!(
//!     FrontEnd::Python.render(&e),
//!     "out: the folder is not empty: force=True replaces its files"
//! );
//! ```

use crate::error::Error;

/// A setting whose words differ from its front ends' rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Setting {
    /// The library's name.
    pub name: &'static str,
    /// The command line's flag without its dashes (`solver` for `--solver`).
    pub flag: &'static str,
    /// The Python package's words.
    pub argument: &'static str,
}

/// The settings whose words are not `--name-with-hyphens` on the command line or `name` in
/// Python: switches (given as `force=True` in Python), and names that differ. An environment
/// variable (a name in capitals, `RDLIDAR_MEMORY_LIMIT`) is its own word in every front end.
pub const SETTINGS: &[Setting] = &[
    Setting {
        name: "force",
        flag: "force",
        argument: "force=True",
    },
    Setting {
        name: "stream_codes",
        flag: "stream-codes",
        argument: "stream_codes=True",
    },
    Setting {
        name: "fill_unobserved",
        flag: "fill-unobserved",
        argument: "fill_unobserved=True",
    },
    Setting {
        name: "precision",
        flag: "precision",
        argument: "dtype",
    },
    Setting {
        name: "method",
        flag: "solver",
        argument: "solver",
    },
];

/// A front end: who fills the settings and reads the errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrontEnd {
    /// The `rdlidar` command line: flags.
    CommandLine,
    /// The Python package: keyword arguments.
    Python,
}

impl FrontEnd {
    /// The words of setting `name`: its entry in [`SETTINGS`], or the front end's rule.
    pub fn word(self, name: &str) -> String {
        if name.starts_with(|c: char| c.is_ascii_uppercase()) {
            return name.to_string();
        }
        match (SETTINGS.iter().find(|s| s.name == name), self) {
            (Some(s), FrontEnd::CommandLine) => format!("--{}", s.flag),
            (Some(s), FrontEnd::Python) => s.argument.to_string(),
            (None, FrontEnd::CommandLine) => format!("--{}", name.replace('_', "-")),
            (None, FrontEnd::Python) => name.to_string(),
        }
    }

    /// `text` with every setting between backticks in this front end's words: `` `name` `` (a
    /// lower-case name of letters, digits and underscores) as [`word`](Self::word) gives it, and
    /// a setting with its value, `` `name=value` ``, as the front end writes it (`--scene png`,
    /// `scene="png"`, `adcs=2`); other backticked text stays.
    pub fn words(self, text: &str) -> String {
        let mut out = String::with_capacity(text.len());
        let mut rest = text;
        while let Some(open) = rest.find('`') {
            out.push_str(&rest[..open]);
            let after = &rest[open + 1..];
            match after.find('`') {
                Some(close) if is_setting(&after[..close]) => {
                    out.push_str(&self.word(&after[..close]));
                    rest = &after[close + 1..];
                }
                Some(close) if is_setting_value(&after[..close]) => {
                    out.push_str(&self.with_value(&after[..close]));
                    rest = &after[close + 1..];
                }
                _ => {
                    out.push('`');
                    rest = after;
                }
            }
        }
        out.push_str(rest);
        out
    }

    /// What is wrong, in this front end's words, for a front end that names the setting
    /// itself (a flag's parser): an invalid setting's reason, or the whole error.
    pub fn reason(self, e: &Error) -> String {
        match e {
            Error::InvalidParameter { reason, .. } => self.words(reason),
            e => self.words(&e.to_string()),
        }
    }

    /// `name=value` as this front end gives a setting its value.
    fn with_value(self, token: &str) -> String {
        let (name, value) = token.split_once('=').unwrap_or((token, ""));
        match self {
            FrontEnd::CommandLine => format!("{} {value}", self.word(name)),
            FrontEnd::Python if value.parse::<f64>().is_ok() => format!("{name}={value}"),
            FrontEnd::Python => format!("{name}=\"{value}\""),
        }
    }

    /// An error in this front end's words: an invalid setting as `word: reason`, any other error
    /// as the library writes it; the settings its text names in backticks, in words too.
    pub fn render(self, e: &Error) -> String {
        match e {
            Error::InvalidParameter { name, reason } => {
                format!("{}: {}", self.word(name), self.words(reason))
            }
            e => self.words(&e.to_string()),
        }
    }
}

/// Whether `token` is `name=value`: a setting's name, and a value of letters, digits, `.`,
/// `-` and `_`.
fn is_setting_value(token: &str) -> bool {
    token.split_once('=').is_some_and(|(name, value)| {
        is_setting(name)
            && !value.is_empty()
            && value
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_'))
    })
}

/// Whether `token` is a setting's name: lower-case letters, digits and underscores, starting
/// with a letter.
fn is_setting(token: &str) -> bool {
    token.starts_with(|c: char| c.is_ascii_lowercase())
        && token
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}
