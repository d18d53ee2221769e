//! The recording CSV reader (RECORDING_FORMAT.md), streaming: the file is read through a
//! buffer, never held whole, and each cell is parsed where it lies (no per-record string, no
//! trim unless a cell does not parse as it is). Line numbers are found only when an error
//! needs one, by counting the newlines before the record's last byte — the csv crate's own
//! count leaves out the comment and blank lines it skips.

use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};

use super::{OPTIONAL, REQUIRED, Recording};
use crate::error::{Error, Location, Result};

/// Where an error's line number comes from: the text itself, or the file read again.
pub(super) enum Lines<'a> {
    /// Text in memory.
    Text(&'a [u8]),
    /// A file on disk, re-read on the error path only.
    File(&'a Path),
}

impl Lines<'_> {
    /// The 1-based line of the record whose bytes end at `end` (absolute offset in the input;
    /// trailing line ends are skipped back over).
    fn line_of(&self, end: u64) -> u64 {
        let owned;
        let bytes: &[u8] = match self {
            Lines::Text(b) => b,
            Lines::File(p) => {
                owned = std::fs::read(p).unwrap_or_default();
                &owned
            }
        };
        let mut end = (end as usize).min(bytes.len());
        while end > 0 && matches!(bytes[end - 1], b'\n' | b'\r') {
            end -= 1;
        }
        bytes[..end].iter().filter(|&&b| b == b'\n').count() as u64 + 1
    }
}

/// What precedes the rows: the metadata and the header line.
struct Preamble {
    /// `key: value` metadata lines.
    meta: Vec<(String, String)>,
    /// The header line as read (empty if the input ended first).
    header: String,
    /// Bytes before the header line.
    header_offset: u64,
    /// Lines before the header line.
    meta_lines: u64,
    /// Bytes up to the end of the header line (where the rows start).
    data_offset: u64,
}

/// Reads the metadata lines and the header line, up to and including the header.
fn preamble(input: &mut impl BufRead, source: &Path) -> Result<Preamble> {
    let mut meta = Vec::new();
    let (mut consumed, mut lines) = (0u64, 0u64);
    let mut line = String::new();
    loop {
        line.clear();
        let n = input.read_line(&mut line).map_err(|e| match e.kind() {
            std::io::ErrorKind::InvalidData => Error::Malformed {
                at: Location {
                    file: source.to_owned(),
                    line: lines + 1,
                    column: None,
                },
                message: "not UTF-8 text (a recording CSV is text; bags are `.mcap`)".into(),
            },
            _ => Error::Io {
                path: source.to_owned(),
                source: e,
            },
        })?;
        if n == 0 {
            return Ok(Preamble {
                meta,
                header: String::new(),
                header_offset: consumed,
                meta_lines: lines,
                data_offset: consumed,
            });
        }
        consumed += n as u64;
        // A byte-order mark (spreadsheet exports) is not part of the first line.
        let text = if lines == 0 {
            line.strip_prefix('\u{feff}').unwrap_or(&line)
        } else {
            &line
        };
        let trimmed = text.trim();
        if let Some(body) = trimmed.strip_prefix('#') {
            if let Some((k, v)) = body.trim_start_matches('#').split_once(':') {
                meta.push((k.trim().to_owned(), v.trim().to_owned()));
            }
        } else if !trimmed.is_empty() {
            return Ok(Preamble {
                meta,
                header: text.to_owned(),
                header_offset: consumed - n as u64,
                meta_lines: lines,
                data_offset: consumed,
            });
        }
        lines += 1;
    }
}

/// Parses a recording from `input` (see [`Recording::from_csv_str`] for the format and the
/// errors) into `columns` (the others are not parsed, so not checked); `source` names it,
/// `lines` finds line numbers for errors.
pub(super) fn parse(
    mut input: impl BufRead,
    source: PathBuf,
    lines: &Lines<'_>,
    columns: Columns,
) -> Result<Recording> {
    let Preamble {
        meta,
        header,
        header_offset,
        meta_lines,
        ..
    } = preamble(&mut input, &source)?;
    let header_line = meta_lines + 1;
    let stream = std::io::Cursor::new(header.into_bytes()).chain(input);
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .comment(Some(b'#'))
        .buffer_capacity(1 << 16)
        .from_reader(stream);
    let csv_error = |e: &csv::Error, end: Option<u64>| match e.kind() {
        csv::ErrorKind::Io(io) => Error::Io {
            path: source.clone(),
            source: std::io::Error::new(io.kind(), io.to_string()),
        },
        _ => Error::Malformed {
            at: Location {
                file: source.clone(),
                line: end.map_or(header_line, |b| lines.line_of(header_offset + b)),
                column: None,
            },
            message: e.to_string(),
        },
    };
    let headers: Vec<String> = rdr
        .headers()
        .map_err(|e| csv_error(&e, None))?
        .iter()
        .map(|h| h.trim().to_owned())
        .collect();
    let (req_idx, mut opt_idx) = column_indices(&headers, &source, header_line)?;
    if columns == Columns::Required {
        opt_idx.fill(None);
    }
    let mut req: [Vec<f64>; 5] = Default::default();
    let mut opt: Vec<Option<Vec<f64>>> = opt_idx.iter().map(|i| i.map(|_| Vec::new())).collect();
    let mut record = csv::ByteRecord::new();
    loop {
        match rdr.read_byte_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_error(&e, Some(rdr.position().byte()))),
        }
        let at = |i: usize, name: &str| Location {
            file: source.clone(),
            line: lines.line_of(header_offset + rdr.position().byte()),
            column: Some((i + 1, name.to_owned())),
        };
        let cell = |i: usize, name: &str| -> Result<f64> {
            let raw = record.get(i).unwrap_or_default();
            let x = number(raw).ok_or_else(|| Error::BadValue {
                at: at(i, name),
                message: format!("`{}` is not a number", String::from_utf8_lossy(raw).trim()),
            })?;
            if x.is_finite() {
                Ok(x)
            } else {
                Err(Error::BadValue {
                    at: at(i, name),
                    message: format!("`{}` is not finite", String::from_utf8_lossy(raw).trim()),
                })
            }
        };
        for ((col, &i), name) in req.iter_mut().zip(&req_idx).zip(REQUIRED) {
            col.push(cell(i, name)?);
        }
        for ((col, i), name) in opt.iter_mut().zip(&opt_idx).zip(OPTIONAL) {
            if let (Some(col), Some(i)) = (col.as_mut(), i) {
                col.push(cell(*i, name)?);
            }
        }
        if let [.., a, b] = req[0].as_slice()
            && b <= a
        {
            return Err(Error::TimeNotIncreasing {
                at: at(req_idx[0], "t"),
                t: *b,
                previous: *a,
            });
        }
    }
    if req[0].is_empty() {
        return Err(Error::TooShort {
            file: source,
            samples: 0,
            needed: 2,
            why: "a recording needs data rows after the header".into(),
        });
    }
    Ok(recording_of(source, meta, req, opt))
}

/// Where the [`REQUIRED`] columns (each) and the [`OPTIONAL`] ones (where present) are among
/// `headers`, read on line `header_line` of `source`.
///
/// # Errors
/// [`Error::MissingColumn`] for the first required column missing.
fn column_indices(
    headers: &[String],
    source: &Path,
    header_line: u64,
) -> Result<([usize; 5], Vec<Option<usize>>)> {
    let find = |name: &str| headers.iter().position(|h| h == name);
    let mut req_idx = [0usize; 5];
    for (slot, name) in req_idx.iter_mut().zip(REQUIRED) {
        *slot = find(name).ok_or_else(|| Error::MissingColumn {
            file: source.to_owned(),
            line: header_line,
            column: name.into(),
            header: headers.join(","),
        })?;
    }
    Ok((req_idx, OPTIONAL.iter().map(|n| find(n)).collect()))
}

/// The recording of the five required columns (in [`REQUIRED`] order) and the optional ones
/// (in [`OPTIONAL`] order, `None` where absent).
fn recording_of(
    source: PathBuf,
    meta: Vec<(String, String)>,
    [t, v_ref, w_ref, v, w]: [Vec<f64>; 5],
    optional: impl IntoIterator<Item = Option<Vec<f64>>>,
) -> Recording {
    let mut opt = optional.into_iter();
    let mut next = || opt.next().flatten();
    Recording {
        source,
        meta,
        t,
        v_ref,
        w_ref,
        v,
        w,
        x: next(),
        y: next(),
        phi: next(),
        wl: next(),
        wr: next(),
    }
}

/// A cell as a number: as it is, else with the blanks around it trimmed (`" 0.5 "`).
fn number(raw: &[u8]) -> Option<f64> {
    number_str(std::str::from_utf8(raw).ok()?)
}

/// [`number`] of a cell already known to be text.
fn number_str(text: &str) -> Option<f64> {
    text.parse().ok().or_else(|| text.trim().parse().ok())
}

/// Which columns a read keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Columns {
    /// Every column of the format the file has (required and optional).
    #[default]
    All,
    /// The five required columns only (`t`, `v_ref`, `w_ref`, `v`, `w`): what identification
    /// needs; the pose and wheel columns are skipped unparsed.
    Required,
}

/// Files read in parts without falling back (tests check that the split path ran).
#[cfg(test)]
pub(super) static SPLIT_READS: std::sync::atomic::AtomicUsize =
    std::sync::atomic::AtomicUsize::new(0);

/// Data below this many bytes is parsed on the calling thread.
pub(super) const PARALLEL_MIN_BYTES: u64 = 4 << 20;

/// Reads a recording file with its data rows split at line ends into one part per core of
/// rayon's pool, each part parsed on its own thread from its own file handle (streaming, as
/// [`parse`]). Any error or irregularity in any part — a bad cell, a ragged row, time not
/// increasing, a quote anywhere, a header line that is not one plain record — makes it read the file again with [`parse`],
/// whose error (file, line, column) is the one reported: the fast path never decides an error.
pub(super) fn read_file(path: &Path, columns: Columns) -> Result<Recording> {
    // At least two parts, so that the split path is the same on every machine.
    let parts = rayon::current_num_threads().clamp(2, 8);
    read_file_in(path, columns, parts, PARALLEL_MIN_BYTES)
}

/// [`read_file`] with the rows in `parts` parts (1: the sequential reader) when the file has
/// at least `min_bytes` bytes.
pub(super) fn read_file_in(
    path: &Path,
    columns: Columns,
    parts: usize,
    min_bytes: u64,
) -> Result<Recording> {
    let io = |source| Error::Io {
        path: path.to_owned(),
        source,
    };
    let sequential = || -> Result<Recording> {
        let file = std::fs::File::open(path).map_err(io)?;
        parse(
            std::io::BufReader::with_capacity(1 << 20, file),
            path.to_owned(),
            &Lines::File(path),
            columns,
        )
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len < min_bytes || parts < 2 {
        return sequential();
    }
    let mut head = std::io::BufReader::new(std::fs::File::open(path).map_err(io)?);
    let Ok(pre) = preamble(&mut head, path) else {
        return sequential();
    };
    let start = pre.data_offset;
    // The header must read as one plain record, as the sequential reader's csv parser reads it:
    // a carriage return inside the line ends a record there, a quote changes the fields.
    let line = pre.header.strip_suffix('\n').unwrap_or(&pre.header);
    let line = line.strip_suffix('\r').unwrap_or(line);
    if line.contains(['\r', '"']) {
        return sequential();
    }
    let headers: Vec<&str> = line.split(',').map(str::trim).collect();
    let find = |name: &str| headers.iter().position(|h| *h == name);
    let Some(req): Option<Vec<usize>> = REQUIRED.iter().map(|n| find(n)).collect() else {
        return sequential();
    };
    let opt: Vec<usize> = match columns {
        Columns::All => OPTIONAL.iter().filter_map(|n| find(n)).collect(),
        Columns::Required => Vec::new(),
    };
    let opt_present: Vec<bool> = OPTIONAL.iter().map(|n| find(n).is_some()).collect();
    let wanted: Vec<usize> = req.iter().chain(&opt).copied().collect();
    let Some(bounds) = split_points(path, start, len, parts) else {
        return sequential();
    };
    let parts: Vec<Option<Vec<Vec<f64>>>> = {
        use rayon::prelude::*;
        bounds
            .par_windows(2)
            .map(|w| parse_part(path, w[0], w[1], &wanted, headers.len()))
            .collect()
    };
    match join_parts(parts) {
        Some(cols) => {
            #[cfg(test)]
            SPLIT_READS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            Ok(assemble(path, pre.meta, cols, &opt_present, columns))
        }
        None => sequential(),
    }
}

/// `parts + 1` byte offsets from `start` to `len`, each inner one moved to just after the
/// next line end; `None` if a part would be empty.
fn split_points(path: &Path, start: u64, len: u64, parts: usize) -> Option<Vec<u64>> {
    use std::io::{Seek, SeekFrom};
    let mut points = vec![start];
    let mut file = std::io::BufReader::new(std::fs::File::open(path).ok()?);
    for i in 1..parts as u64 {
        let guess = start + (len - start) * i / parts as u64;
        file.seek(SeekFrom::Start(guess)).ok()?;
        let mut skipped = Vec::new();
        let n = file.read_until(b'\n', &mut skipped).ok()? as u64;
        let point = guess + n;
        if point <= *points.last()? || point >= len {
            return None;
        }
        points.push(point);
    }
    points.push(len);
    Some(points)
}

/// Parses the rows in bytes `[a, b)` of `path` into the `wanted` columns (finite numbers,
/// `width` cells a row, time strictly increasing); `None` on anything else. The lines are
/// found with `memchr` and split at commas, each wanted cell parsed where it lies: what the
/// csv crate does for a file with no quote and no lone carriage return, which is all this
/// path accepts (a comment line is one that starts with `#` and ends with a line end, a blank
/// line is skipped, a CRLF line end is one line end); anything else goes back to the sequential
/// reader.
fn parse_part(
    path: &Path,
    a: u64,
    b: u64,
    wanted: &[usize],
    width: usize,
) -> Option<Vec<Vec<f64>>> {
    use std::io::{Seek, SeekFrom};
    let mut file = std::fs::File::open(path).ok()?;
    file.seek(SeekFrom::Start(a)).ok()?;
    let mut input = file.take(b - a);
    // Rows of this part, guessed from its size and ~12 bytes a cell, to grow the columns once.
    let guess = ((b - a) / (12 * width.max(1) as u64)) as usize;
    let mut cols: Vec<Vec<f64>> = wanted.iter().map(|_| Vec::with_capacity(guess)).collect();
    // Which output column each cell goes to.
    let mut slot = vec![usize::MAX; width];
    for (o, &i) in wanted.iter().enumerate() {
        *slot.get_mut(i)? = o;
    }
    let cells = Cells {
        slot: &slot,
        width,
        last: wanted.iter().max().map_or(0, |&i| i + 1),
    };
    let mut buf = vec![0u8; 1 << 20];
    let (mut filled, mut first) = (0, true);
    loop {
        let n = input.read(&mut buf[filled..]).ok()?;
        filled += n;
        // The csv parser drops a byte-order mark at the start of its input; here that is the
        // middle of the file, where the sequential reader keeps it (and reads another line).
        if first && (filled >= 3 || n == 0) {
            if buf[..filled].starts_with(b"\xEF\xBB\xBF") {
                return None;
            }
            first = false;
        }
        let end = match (n, memchr::memrchr(b'\n', &buf[..filled])) {
            (0, _) => filled,
            (_, Some(i)) => i + 1,
            (_, None) => {
                if filled == buf.len() {
                    buf.resize(2 * buf.len(), 0);
                }
                continue;
            }
        };
        let mut start = 0;
        // Most chunks are plain ASCII with no quote and no carriage return: checked once here
        // rather than line by line.
        let chunk = &buf[..end];
        if memchr::memchr2(b'"', b'\r', chunk).is_none() && chunk.is_ascii() {
            for stop in memchr::memchr_iter(b'\n', chunk) {
                plain_line(&buf[start..stop], &cells, &mut cols)?;
                start = stop + 1;
            }
        }
        let from = start;
        for stop in memchr::memchr_iter(b'\n', &buf[from..end]).map(|i| from + i) {
            parse_line(&buf[start..stop], &cells, &mut cols)?;
            start = stop + 1;
        }
        // The input's last line without a line end. The csv crate reads a `#` line there as a
        // record, not a comment (a fuzzer found it): such a file goes back to it.
        if start < end {
            if buf[start] == b'#' {
                return None;
            }
            parse_line(&buf[start..end], &cells, &mut cols)?;
        }
        buf.copy_within(end..filled, 0);
        filled -= end;
        if n == 0 {
            return Some(cols);
        }
    }
}

/// Where a row's cells go: `slot[i]` is cell i's output column (`usize::MAX`: skipped), of
/// `width` cells a row; cells from `last` on are all skipped.
struct Cells<'a> {
    slot: &'a [usize],
    width: usize,
    last: usize,
}

/// One line (without its `\n`) of [`parse_part`] into `cols`; `None` where the csv crate might
/// read it otherwise, or a cell is not a finite number, or time does not increase.
fn parse_line(line: &[u8], cells: &Cells<'_>, cols: &mut [Vec<f64>]) -> Option<()> {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    if line.is_empty() || (line[0] == b'#' && memchr::memchr(b'\r', line).is_none()) {
        return Some(());
    }
    if memchr::memchr2(b'"', b'\r', line).is_some() {
        return None;
    }
    if line.is_ascii() {
        cells_ascii(line, cells, cols)?;
    } else {
        cells_utf8(line, cells, cols)?;
    }
    increasing(cols)
}

/// [`parse_line`] of a line known to be ASCII with no quote and no carriage return.
#[inline]
fn plain_line(line: &[u8], cells: &Cells<'_>, cols: &mut [Vec<f64>]) -> Option<()> {
    if line.is_empty() || line[0] == b'#' {
        return Some(());
    }
    cells_ascii(line, cells, cols)?;
    increasing(cols)
}

/// Time (the first column) increases from the previous row to the last.
#[inline]
fn increasing(cols: &[Vec<f64>]) -> Option<()> {
    match cols[0].as_slice() {
        [.., p, q] if q <= p => None,
        _ => Some(()),
    }
}

/// The cells of an ASCII line (which is UTF-8): each wanted one parsed from its bytes where it
/// lies (`fast_float2`, the algorithm std's parser adopted, so the same values), the number
/// required to end at the cell's end — else the cell is read as [`number`] reads it (blanks
/// around it trimmed); the others skipped, those after the last wanted one by counting their
/// commas. `None` for a cell that is no finite number or a row of other than `width` cells.
fn cells_ascii(line: &[u8], cells: &Cells<'_>, cols: &mut [Vec<f64>]) -> Option<()> {
    let Cells { slot, width, last } = *cells;
    let mut at = 0;
    for (cell, &o) in slot.iter().enumerate().take(last) {
        let rest = &line[at..];
        let end =
            |from: usize| from + memchr::memchr(b',', &rest[from..]).unwrap_or(rest.len() - from);
        let used = if o == usize::MAX {
            end(0)
        } else {
            let (x, used) = match fast_float2::parse_partial::<f64, _>(rest) {
                Ok((x, used)) if matches!(rest.get(used), None | Some(b',')) => (x, used),
                _ => {
                    let stop = end(0);
                    (number(&rest[..stop])?, stop)
                }
            };
            if !x.is_finite() {
                return None;
            }
            cols[o].push(x);
            used
        };
        at += used;
        if cell + 1 < width {
            if line.get(at) != Some(&b',') {
                return None;
            }
            at += 1;
        } else if at != line.len() {
            return None;
        }
    }
    // The skipped cells after the last wanted one: width − last of them, so one comma fewer
    // (`at` is past the comma that ends cell last − 1).
    if last < width {
        let commas = memchr::memchr_iter(b',', &line[at..]).count();
        if commas + 1 != width - last {
            return None;
        }
    }
    Some(())
}

/// [`cells_ascii`] for a line with other characters: one UTF-8 check for the line (a line that
/// fails it goes back to the sequential reader, which checks cell by cell), then each wanted
/// cell read as [`number`] reads it.
fn cells_utf8(line: &[u8], cells: &Cells<'_>, cols: &mut [Vec<f64>]) -> Option<()> {
    let Cells { slot, width, .. } = *cells;
    // Commas are ASCII, so every cell is a `str` slice of the line.
    let text = std::str::from_utf8(line).ok()?;
    let (mut cell, mut start) = (0, 0);
    for stop in memchr::memchr_iter(b',', line).chain(std::iter::once(line.len())) {
        let o = *slot.get(cell)?;
        if o != usize::MAX {
            let x = number_str(text.get(start..stop)?)?;
            if !x.is_finite() {
                return None;
            }
            cols[o].push(x);
        }
        (cell, start) = (cell + 1, stop + 1);
    }
    (cell == width).then_some(())
}

/// The parts' columns end to end, the first part's grown in place; `None` if a part failed,
/// one is empty, or time does not increase across a split.
fn join_parts(parts: Vec<Option<Vec<Vec<f64>>>>) -> Option<Vec<Vec<f64>>> {
    let mut parts = parts.into_iter();
    let mut cols = parts.next()??;
    let rest: Vec<Vec<Vec<f64>>> = parts.collect::<Option<_>>()?;
    for (k, col) in cols.iter_mut().enumerate() {
        col.reserve_exact(rest.iter().map(|p| p[k].len()).sum());
    }
    for part in rest {
        let (&last, &first) = (cols[0].last()?, part[0].first()?);
        if first <= last {
            return None;
        }
        for (col, more) in cols.iter_mut().zip(part) {
            col.extend_from_slice(&more);
        }
    }
    cols[0].first()?;
    Some(cols)
}

/// The recording from the joined columns: the five required first, then the optional ones
/// present in the file (when kept).
fn assemble(
    path: &Path,
    meta: Vec<(String, String)>,
    cols: Vec<Vec<f64>>,
    present: &[bool],
    columns: Columns,
) -> Recording {
    let mut cols = cols.into_iter();
    let req: [Vec<f64>; 5] = std::array::from_fn(|_| cols.next().unwrap_or_default());
    let opt: Vec<Option<Vec<f64>>> = present
        .iter()
        .map(|&p| {
            (p && columns == Columns::All)
                .then(|| cols.next())
                .flatten()
        })
        .collect();
    recording_of(path.to_owned(), meta, req, opt)
}
