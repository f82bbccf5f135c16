//! The crate's one error type.
//!
//! Every error names the file (when there is one) and says what is wrong in one sentence,
//! so the CLI can print it as is. No panics on bad input: readers return these instead.

use std::fmt;
use std::path::{Path, PathBuf};

/// What went wrong, coarse enough to match on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// Reading or writing a file failed at the operating-system level.
    Io,
    /// A file exists but its content is malformed.
    Parse,
    /// The content is well-formed but describes something we do not support
    /// (e.g. a distorted COLMAP camera model).
    Unsupported,
    /// Arguments or data are inconsistent (wrong sizes, NaN where a number is required).
    Invalid,
    /// The inputs are valid but admit no result: a clip in which an intermediate camera
    /// sees neither end frame, or between end frames of different sizes; a clip's video
    /// depth that no alignment fits. A caller that can do without the result records it
    /// and goes on (SPEC.md §20.3–20.4); to every other caller it is an error like
    /// [`ErrorKind::Invalid`].
    Degenerate,
}

/// An error with a human-readable message and, when relevant, the file it concerns.
#[derive(Debug)]
pub struct Error {
    pub kind: ErrorKind,
    pub path: Option<PathBuf>,
    pub message: String,
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> Self {
        Error {
            kind,
            path: None,
            message: message.into(),
        }
    }
    pub fn parse(path: &Path, message: impl Into<String>) -> Self {
        Error {
            kind: ErrorKind::Parse,
            path: Some(path.to_path_buf()),
            message: message.into(),
        }
    }
    pub fn unsupported(path: &Path, message: impl Into<String>) -> Self {
        Error {
            kind: ErrorKind::Unsupported,
            path: Some(path.to_path_buf()),
            message: message.into(),
        }
    }
    pub fn invalid(message: impl Into<String>) -> Self {
        Error::new(ErrorKind::Invalid, message)
    }
    pub fn degenerate(message: impl Into<String>) -> Self {
        Error::new(ErrorKind::Degenerate, message)
    }
    pub fn io(path: &Path, err: std::io::Error) -> Self {
        Error {
            kind: ErrorKind::Io,
            path: Some(path.to_path_buf()),
            message: err.to_string(),
        }
    }
    /// Attach a path if the error has none yet.
    pub fn at(mut self, path: &Path) -> Self {
        if self.path.is_none() {
            self.path = Some(path.to_path_buf());
        }
        self
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.path {
            Some(p) => write!(f, "{}: {}", p.display(), self.message),
            None => f.write_str(&self.message),
        }
    }
}

impl std::error::Error for Error {}

/// The crate's one text idiom for a fieldless enum, from one table of names: `ALL` (every
/// value, in order), `name()`, `Display` and `FromStr` (an unknown name is an
/// [`ErrorKind::Invalid`] error listing the names). Configuration files and the command line
/// both read these names.
macro_rules! text_enum {
    ($t:ident, $what:literal, { $($v:ident => $s:literal),+ $(,)? }) => {
        impl $t {
            /// Every value, in order.
            pub const ALL: [$t; [$($s),+].len()] = [$($t::$v),+];

            /// The value's name in a configuration and on the command line.
            pub fn name(self) -> &'static str {
                match self {
                    $($t::$v => $s),+
                }
            }
        }

        impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl std::str::FromStr for $t {
            type Err = $crate::error::Error;
            fn from_str(s: &str) -> $crate::error::Result<$t> {
                Self::ALL.into_iter().find(|v| v.name() == s).ok_or_else(|| {
                    $crate::error::Error::invalid(format!(
                        concat!("unknown ", $what, " '{}' ({})"),
                        s,
                        [$($s),+].join(", ")
                    ))
                })
            }
        }
    };
}
pub(crate) use text_enum;
