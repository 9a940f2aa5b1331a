//! What can go wrong reading a BVH file, with the place it went wrong.

use std::fmt;

/// A BVH file that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum BvhError {
    /// The text is not valid BVH at `line`, `column` (both 1-based).
    #[error("line {line}, column {column}: {kind}")]
    Syntax {
        /// 1-based line number.
        line: usize,
        /// 1-based column (in bytes).
        column: usize,
        /// What was wrong there.
        kind: SyntaxError,
    },
    /// The file could not be opened or read (including a corrupt gzip stream).
    #[error("reading BVH: {0}")]
    Io(#[from] std::io::Error),
}

impl BvhError {
    /// The syntax error, if this is one.
    pub fn syntax(&self) -> Option<&SyntaxError> {
        match self {
            BvhError::Syntax { kind, .. } => Some(kind),
            BvhError::Io(_) => None,
        }
    }

    /// The 1-based line of a syntax error.
    pub fn line(&self) -> Option<usize> {
        match self {
            BvhError::Syntax { line, .. } => Some(*line),
            BvhError::Io(_) => None,
        }
    }
}

/// A token found where something else was expected, shown the way a user would look for it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Found {
    /// The end of the file.
    EndOfFile,
    /// The end of the line.
    EndOfLine,
    /// A token (cut to 40 characters).
    Token(String),
}

impl Found {
    pub(crate) fn token(text: &str) -> Found {
        const MAX: usize = 40;
        match text.char_indices().nth(MAX) {
            Some((cut, _)) => Found::Token(format!("{}...", &text[..cut])),
            None => Found::Token(text.to_string()),
        }
    }
}

impl fmt::Display for Found {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Found::EndOfFile => f.write_str("end of file"),
            Found::EndOfLine => f.write_str("end of line"),
            Found::Token(t) => write!(f, "{t:?}"),
        }
    }
}

/// The specific way a BVH file is malformed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SyntaxError {
    /// Something other than what the grammar allows here.
    #[error("expected {expected}, found {found}")]
    Expected {
        /// What the grammar allows here.
        expected: &'static str,
        /// What the file has.
        found: Found,
    },
    /// A token that should be a number is not one.
    #[error("expected a number, found {0}")]
    NotANumber(Found),
    /// A number that is NaN or infinite.
    #[error("number {0} is not finite")]
    NonFinite(Found),
    /// An unknown channel name.
    #[error("unknown channel {0}: expected Xposition, Yposition, Zposition, Xrotation, Yrotation or Zrotation")]
    UnknownChannel(Found),
    /// A channel listed twice on one joint.
    #[error("channel {0} is listed twice for this joint")]
    DuplicateChannel(String),
    /// `CHANNELS n` with n outside 0..=6.
    #[error("a joint has at most 6 channels, CHANNELS declares {0}")]
    TooManyChannels(usize),
    /// A joint name used twice.
    #[error("joint name {name:?} is used twice (first at line {first_line})")]
    DuplicateJoint {
        /// The repeated name.
        name: String,
        /// Where it was first used.
        first_line: usize,
    },
    /// A joint name that could not be written back as it is (a carriage return inside it, or a
    /// second white-space-separated `{` at its end).
    #[error("joint name {0} cannot be written back to BVH as it is")]
    BadJointName(Found),
    /// A second `ROOT` after the first hierarchy closed.
    #[error("a second ROOT: anymo reads files with one hierarchy")]
    SecondRoot,
    /// A frame row with the wrong number of values.
    #[error("frame {frame} has {found} values but the hierarchy declares {expected} channels")]
    ValueCount {
        /// 0-based frame index.
        frame: usize,
        /// Channels declared by the hierarchy.
        expected: usize,
        /// Values found on the row.
        found: usize,
    },
    /// Fewer frame rows than `Frames:` declared.
    #[error("the file ends after {found} of the {declared} frames that Frames: declares")]
    MissingFrames {
        /// Frames declared.
        declared: usize,
        /// Rows found.
        found: usize,
    },
    /// More frame rows than `Frames:` declared.
    #[error("more frame rows than the {declared} that Frames: declares")]
    ExtraFrames {
        /// Frames declared.
        declared: usize,
    },
    /// `Frame Time:` zero, negative or not finite.
    #[error("frame time must be a positive number of seconds, found {0}")]
    FrameTime(Found),
    /// `Frames: 0` where the caller needs motion.
    #[error("Frames: 0, but a motion is required here (a skeleton-only file has no frames)")]
    NoFrames,
    /// The hierarchy has no joint at all.
    #[error("the hierarchy has no joints")]
    NoJoints,
}
