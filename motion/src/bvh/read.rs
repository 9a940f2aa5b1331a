//! The BVH reader. The hierarchy is read token by token; the motion section is scanned block by
//! block straight into one `Vec<f32>`, so memory stays near the size of the numbers themselves.

use super::Bvh;
use super::error::{BvhError, Found, SyntaxError};
use crate::skeleton::{Channel, Channels, Joint, Skeleton, SkeletonError, is_writable_name};
use glam::Vec3;
use std::collections::HashMap;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// How strict the reader is about what the file must contain.
#[derive(Clone, Copy, Debug, Default)]
pub struct ReadOptions {
    /// Refuse `Frames: 0` (a skeleton-only file) with [`SyntaxError::NoFrames`].
    pub require_motion: bool,
}

/// Reads a BVH file from any buffered reader.
pub fn read<R: BufRead>(mut reader: R, options: ReadOptions) -> Result<Bvh, BvhError> {
    let mut lexer = Lexer::new(&mut reader);
    let header = parse_header(&mut lexer, options)?;
    let mut scanner = FrameScanner::new(header.skeleton.channel_count(), header.frames, lexer.line_no);
    scanner.scan(&mut reader)?;
    let frames = scanner.finish()?;
    Ok(Bvh { skeleton: header.skeleton, frame_time: header.frame_time, frames, values: scanner.values })
}

/// Reads a BVH text held in memory.
pub fn parse_str(text: &str) -> Result<Bvh, BvhError> {
    read(text.as_bytes(), ReadOptions::default())
}

/// Reads a `.bvh` or gzip-compressed `.bvh.gz` file (recognised by its content, not its name).
pub fn read_path(path: impl AsRef<Path>, options: ReadOptions) -> Result<Bvh, BvhError> {
    const BUFFER: usize = 1 << 18;
    let mut file = BufReader::with_capacity(BUFFER, File::open(path.as_ref())?);
    let gzip = file.fill_buf()?.starts_with(&[0x1f, 0x8b]);
    if gzip {
        read(BufReader::with_capacity(BUFFER, flate2::bufread::MultiGzDecoder::new(file)), options)
    } else {
        read(file, options)
    }
}

struct Header {
    skeleton: Skeleton,
    frames: usize,
    frame_time: f64,
}

/// One whitespace-separated token of the hierarchy with its 1-based position.
struct Token {
    text: String,
    line: usize,
    column: usize,
}

impl Token {
    fn is(&self, keyword: &str) -> bool {
        self.text.eq_ignore_ascii_case(keyword)
    }

    fn error(&self, kind: SyntaxError) -> BvhError {
        BvhError::Syntax { line: self.line, column: self.column, kind }
    }

    fn expected(&self, expected: &'static str) -> BvhError {
        self.error(SyntaxError::Expected { expected, found: Found::token(&self.text) })
    }
}

/// Splits the hierarchy into tokens, line by line, never reading past the line it is on.
struct Lexer<'r, R: BufRead> {
    reader: &'r mut R,
    line: String,
    line_no: usize,
    pos: usize,
    at_eof: bool,
    raw: Vec<u8>,
}

impl<'r, R: BufRead> Lexer<'r, R> {
    fn new(reader: &'r mut R) -> Self {
        Lexer { reader, line: String::new(), line_no: 0, pos: 0, at_eof: false, raw: Vec::new() }
    }

    fn next_line(&mut self) -> Result<bool, BvhError> {
        self.raw.clear();
        if self.reader.read_until(b'\n', &mut self.raw)? == 0 {
            self.at_eof = true;
            return Ok(false);
        }
        self.line_no += 1;
        let text = String::from_utf8_lossy(&self.raw);
        let text = if self.line_no == 1 { text.trim_start_matches('\u{feff}') } else { &text };
        self.line.clear();
        self.line.push_str(text);
        self.pos = 0;
        Ok(true)
    }

    fn skip_space(&mut self) {
        let rest = &self.line[self.pos..];
        self.pos += rest.len() - rest.trim_start().len();
    }

    /// The next token, or `None` at the end of the file.
    fn next(&mut self) -> Result<Option<Token>, BvhError> {
        loop {
            self.skip_space();
            if self.pos < self.line.len() {
                let rest = &self.line[self.pos..];
                let len = rest.find(char::is_whitespace).unwrap_or(rest.len());
                let token = Token { text: rest[..len].to_string(), line: self.line_no, column: self.pos + 1 };
                self.pos += len;
                return Ok(Some(token));
            }
            if !self.next_line()? {
                return Ok(None);
            }
        }
    }

    /// The next token; the end of the file is an error naming what was `expected`.
    fn require(&mut self, expected: &'static str) -> Result<Token, BvhError> {
        match self.next()? {
            Some(t) => Ok(t),
            None => Err(self.end_of_line_error(SyntaxError::Expected { expected, found: Found::EndOfFile })),
        }
    }

    fn keyword(&mut self, keyword: &'static str) -> Result<Token, BvhError> {
        let token = self.require(keyword)?;
        if token.is(keyword) { Ok(token) } else { Err(token.expected(keyword)) }
    }

    /// The next token, which must be on the current line.
    fn on_this_line(&mut self, expected: &'static str) -> Result<Token, BvhError> {
        self.skip_space();
        if self.pos >= self.line.len() {
            return Err(self.end_of_line_error(SyntaxError::Expected { expected, found: Found::EndOfLine }));
        }
        Ok(self.next()?.expect("a token is left on this line"))
    }

    /// The rest of the current line, trimmed: joint names may contain spaces.
    fn rest_of_line(&mut self, expected: &'static str) -> Result<Token, BvhError> {
        self.skip_space();
        let text = self.line[self.pos..].trim_end();
        if text.is_empty() {
            return Err(self.end_of_line_error(SyntaxError::Expected { expected, found: Found::EndOfLine }));
        }
        let token = Token { text: text.to_string(), line: self.line_no, column: self.pos + 1 };
        self.pos = self.line.len();
        Ok(token)
    }

    fn end_of_line(&mut self) -> Result<(), BvhError> {
        self.skip_space();
        if self.pos < self.line.len() {
            let token = self.next()?.expect("a token is left on this line");
            return Err(token.expected("end of line"));
        }
        Ok(())
    }

    fn here(&self, kind: SyntaxError) -> BvhError {
        BvhError::Syntax { line: self.line_no.max(1), column: self.pos + 1, kind }
    }

    /// An error placed just after the last character of the current line.
    fn end_of_line_error(&self, kind: SyntaxError) -> BvhError {
        BvhError::Syntax { line: self.line_no.max(1), column: self.line.trim_end().len() + 1, kind }
    }
}

fn parse_f32(token: &Token) -> Result<f32, BvhError> {
    match fast_float2::parse::<f32, _>(&token.text) {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(token.error(SyntaxError::NonFinite(Found::token(&token.text)))),
        Err(_) => Err(token.error(SyntaxError::NotANumber(Found::token(&token.text)))),
    }
}

fn parse_vec3<R: BufRead>(lexer: &mut Lexer<'_, R>) -> Result<Vec3, BvhError> {
    let mut v = [0.0f32; 3];
    for c in &mut v {
        *c = parse_f32(&lexer.on_this_line("a number")?)?;
    }
    lexer.end_of_line()?;
    Ok(Vec3::from_array(v))
}

struct HierarchyBuilder {
    joints: Vec<Joint>,
    first_seen: HashMap<String, usize>,
}

impl HierarchyBuilder {
    /// Reads `NAME {  OFFSET x y z  [CHANNELS n ...]` after a ROOT or JOINT keyword.
    fn open_joint<R: BufRead>(&mut self, lexer: &mut Lexer<'_, R>, parent: Option<usize>) -> Result<usize, BvhError> {
        let mut name = lexer.rest_of_line("a joint name")?;
        let mut brace_on_name_line = false;
        // `Hips {`: a brace after white space on the name line opens the joint. A brace that
        // is part of the name (`a={`) does not.
        if let Some(stripped) = name.text.strip_suffix('{')
            && stripped.ends_with(char::is_whitespace)
            && !stripped.trim_end().is_empty()
        {
            name.text = stripped.trim_end().to_string();
            brace_on_name_line = true;
        }
        if !is_writable_name(&name.text) {
            return Err(name.error(SyntaxError::BadJointName(Found::token(&name.text))));
        }
        if let Some(&first_line) = self.first_seen.get(&name.text) {
            return Err(name.error(SyntaxError::DuplicateJoint { name: name.text.clone(), first_line }));
        }
        self.first_seen.insert(name.text.clone(), name.line);
        if !brace_on_name_line {
            lexer.keyword("{")?;
        }
        lexer.keyword("OFFSET")?;
        let offset = parse_vec3(lexer)?;
        let channels = parse_channels(lexer)?;
        self.joints.push(Joint { name: name.text, parent, offset, channels, end_site: None });
        Ok(self.joints.len() - 1)
    }
}

/// Reads an optional `CHANNELS n c1 .. cn` line.
fn parse_channels<R: BufRead>(lexer: &mut Lexer<'_, R>) -> Result<Channels, BvhError> {
    lexer.skip_space();
    while lexer.pos >= lexer.line.len() {
        if !lexer.next_line()? {
            return Ok(Channels::default());
        }
        lexer.skip_space();
    }
    let rest = &lexer.line[lexer.pos..];
    if !rest.get(..8).is_some_and(|w| w.eq_ignore_ascii_case("CHANNELS")) {
        return Ok(Channels::default());
    }
    lexer.next()?;
    let count_token = lexer.on_this_line("the channel count")?;
    let count: usize = count_token
        .text
        .parse()
        .map_err(|_| count_token.error(SyntaxError::NotANumber(Found::token(&count_token.text))))?;
    if count > 6 {
        return Err(count_token.error(SyntaxError::TooManyChannels(count)));
    }
    let mut list = Vec::with_capacity(count);
    for _ in 0..count {
        let token = lexer.on_this_line("a channel name")?;
        let channel = Channel::parse(&token.text)
            .ok_or_else(|| token.error(SyntaxError::UnknownChannel(Found::token(&token.text))))?;
        if list.contains(&channel) {
            return Err(token.error(SyntaxError::DuplicateChannel(channel.to_string())));
        }
        list.push(channel);
    }
    lexer.end_of_line()?;
    Ok(Channels::new(list).expect("duplicates were refused above"))
}

fn parse_header<R: BufRead>(lexer: &mut Lexer<'_, R>, options: ReadOptions) -> Result<Header, BvhError> {
    lexer.keyword("HIERARCHY")?;
    lexer.keyword("ROOT")?;
    let mut builder = HierarchyBuilder { joints: Vec::new(), first_seen: HashMap::new() };
    let root = builder.open_joint(lexer, None)?;
    // Joints still open, innermost last; a loop rather than recursion so that deep nesting
    // cannot overflow the stack.
    let mut open = vec![root];
    while let Some(&current) = open.last() {
        let token = lexer.require("JOINT, End Site or }")?;
        if token.is("JOINT") {
            let child = builder.open_joint(lexer, Some(current))?;
            open.push(child);
        } else if token.is("End") {
            lexer.keyword("Site")?;
            lexer.keyword("{")?;
            lexer.keyword("OFFSET")?;
            let offset = parse_vec3(lexer)?;
            lexer.keyword("}")?;
            builder.joints[current].end_site = Some(offset);
        } else if token.is("}") {
            open.pop();
        } else {
            return Err(token.expected("JOINT, End Site or }"));
        }
    }
    let motion = lexer.require("MOTION")?;
    if motion.is("ROOT") {
        return Err(motion.error(SyntaxError::SecondRoot));
    }
    if !motion.is("MOTION") {
        return Err(motion.expected("MOTION"));
    }
    lexer.end_of_line()?;
    lexer.keyword("Frames:")?;
    let frames_token = lexer.on_this_line("the frame count")?;
    let frames: usize = frames_token
        .text
        .parse()
        .map_err(|_| frames_token.error(SyntaxError::NotANumber(Found::token(&frames_token.text))))?;
    if frames == 0 && options.require_motion {
        return Err(frames_token.error(SyntaxError::NoFrames));
    }
    lexer.end_of_line()?;
    lexer.keyword("Frame")?;
    lexer.keyword("Time:")?;
    let time_token = lexer.on_this_line("the frame time")?;
    let frame_time = match fast_float2::parse::<f64, _>(&time_token.text) {
        Ok(t) if t.is_finite() && t > 0.0 => t,
        Ok(_) => return Err(time_token.error(SyntaxError::FrameTime(Found::token(&time_token.text)))),
        Err(_) => return Err(time_token.error(SyntaxError::NotANumber(Found::token(&time_token.text)))),
    };
    lexer.end_of_line()?;
    let skeleton = Skeleton::new(builder.joints).map_err(|e| match e {
        SkeletonError::Empty => lexer.here(SyntaxError::NoJoints),
        other => unreachable!("the parser builds valid trees: {other}"),
    })?;
    Ok(Header { skeleton, frames, frame_time })
}

/// Reads frame rows straight into a flat value array, checking each row's length.
struct FrameScanner {
    channels: usize,
    declared: usize,
    frames: usize,
    values: Vec<f32>,
    line: usize,
    max_row_bytes: usize,
}

/// The most values reserved up front, whatever `Frames:` claims (a hostile header must not
/// make the reader allocate gigabytes before it has seen a single row).
const MAX_RESERVE: usize = 1 << 26;

impl FrameScanner {
    fn new(channels: usize, declared: usize, line: usize) -> Self {
        let reserve = channels.saturating_mul(declared).min(MAX_RESERVE);
        FrameScanner {
            channels,
            declared,
            frames: 0,
            values: Vec::with_capacity(reserve),
            line,
            max_row_bytes: channels.saturating_mul(64).saturating_add(4096),
        }
    }

    fn scan<R: Read + BufRead>(&mut self, reader: &mut R) -> Result<(), BvhError> {
        let mut carry: Vec<u8> = Vec::new();
        loop {
            let buf = reader.fill_buf()?;
            let len = buf.len();
            if len == 0 {
                if !carry.is_empty() {
                    self.scan_rows(&carry)?;
                }
                return Ok(());
            }
            let consumed = match buf.iter().rposition(|&b| b == b'\n') {
                None => {
                    carry.extend_from_slice(buf);
                    if carry.len() > self.max_row_bytes {
                        return Err(self.error(
                            1,
                            SyntaxError::Expected {
                                expected: "a frame row of numbers",
                                found: Found::token("a row longer than any row of the declared channels"),
                            },
                        ));
                    }
                    len
                }
                Some(newline) if carry.is_empty() => {
                    self.scan_rows(&buf[..=newline])?;
                    newline + 1
                }
                Some(newline) => {
                    carry.extend_from_slice(&buf[..=newline]);
                    self.scan_rows(&carry)?;
                    carry.clear();
                    newline + 1
                }
            };
            reader.consume(consumed);
        }
    }

    fn error(&self, column: usize, kind: SyntaxError) -> BvhError {
        BvhError::Syntax { line: self.line, column, kind }
    }

    /// Scans whole rows (the last one may lack its newline at the end of the file).
    fn scan_rows(&mut self, bytes: &[u8]) -> Result<(), BvhError> {
        let n = bytes.len();
        let mut i = 0;
        while i < n {
            self.line += 1;
            let row_start = i;
            let before = self.values.len();
            loop {
                while i < n && matches!(bytes[i], b' ' | b'\t' | b'\r') {
                    i += 1;
                }
                if i >= n || bytes[i] == b'\n' {
                    i += 1;
                    break;
                }
                let (value, len) = match fast_float2::parse_partial::<f32, _>(&bytes[i..]) {
                    Ok(parsed) => parsed,
                    Err(_) => return Err(self.error(i - row_start + 1, SyntaxError::NotANumber(token_at(bytes, i)))),
                };
                let end = i + len;
                if end < n && !matches!(bytes[end], b' ' | b'\t' | b'\r' | b'\n') {
                    return Err(self.error(i - row_start + 1, SyntaxError::NotANumber(token_at(bytes, i))));
                }
                if !value.is_finite() {
                    return Err(self.error(i - row_start + 1, SyntaxError::NonFinite(token_at(bytes, i))));
                }
                if self.values.len() - before == self.channels {
                    return Err(self.row_length_error(before, bytes, i));
                }
                self.values.push(value);
                i = end;
            }
            let found = self.values.len() - before;
            if found == 0 {
                // A skeleton without channels has empty frame rows; count them, so that a
                // claim of millions of frames needs the rows to back it.
                if self.channels == 0 && self.frames < self.declared {
                    self.frames += 1;
                }
                continue;
            }
            if self.frames == self.declared {
                return Err(self.error(1, SyntaxError::ExtraFrames { declared: self.declared }));
            }
            if found != self.channels {
                return Err(
                    self.error(1, SyntaxError::ValueCount { frame: self.frames, expected: self.channels, found })
                );
            }
            self.frames += 1;
        }
        Ok(())
    }

    /// A row with more values than channels: count the rest of the row for the message.
    fn row_length_error(&self, before: usize, bytes: &[u8], from: usize) -> BvhError {
        let rest = &bytes[from..];
        let row = &rest[..rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len())];
        let extra = row.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty()).count();
        if self.frames == self.declared {
            return self.error(1, SyntaxError::ExtraFrames { declared: self.declared });
        }
        let found = self.values.len() - before + extra;
        self.error(1, SyntaxError::ValueCount { frame: self.frames, expected: self.channels, found })
    }

    /// Checks the row count against `Frames:` and returns it.
    fn finish(&self) -> Result<usize, BvhError> {
        if self.frames < self.declared {
            return Err(self.error(1, SyntaxError::MissingFrames { declared: self.declared, found: self.frames }));
        }
        Ok(self.frames)
    }
}

fn token_at(bytes: &[u8], start: usize) -> Found {
    let rest = &bytes[start..];
    let end = rest.iter().position(|b| b.is_ascii_whitespace()).unwrap_or(rest.len());
    Found::token(&String::from_utf8_lossy(&rest[..end]))
}
