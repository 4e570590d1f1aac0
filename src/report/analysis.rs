//! The report's "Analysis" section: what `granular analyze` left in the campaign's
//! [`Campaign::analysis_dir`], shown as files, not physics (the report imports no analysis):
//! every small table there (`*.parquet` of at most [`MAX_TABLE_ROWS`] rows, e.g.
//! `analysis_fits`) as an HTML table of its columns, larger ones by their row count, and every
//! figure `figures/*.svg` as an `<img>` with the SVG in a `data:` URI (an image cannot run a
//! script or load anything, whatever the file holds). No directory, no section.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use arrow_array::cast::AsArray;
use arrow_array::types::{Float64Type, Int32Type, Int64Type, UInt32Type, UInt64Type};
use arrow_array::{Array, RecordBatch};
use arrow_schema::DataType;

use super::escape;
use crate::campaign::Campaign;
use crate::fsutil::{self, Kind};
use crate::store::parquet_io;

/// Tables with more rows are named with their row count only.
pub const MAX_TABLE_ROWS: usize = 200;
/// Larger figure files are left out (with a note).
pub const MAX_FIGURE_BYTES: u64 = 8 << 20;

/// The regular files of `dir` ending in `.ext`, sorted (hidden ones left out); a link (the
/// directory or a file) is not followed: not granular's own (`integrity` names it).
fn files(dir: &Path, ext: &str) -> Vec<PathBuf> {
    if !is_own(dir, Kind::Dir) {
        return Vec::new();
    }
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|it| {
            it.filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| {
                    let n = p.file_name().map(|n| n.to_string_lossy().into_owned());
                    n.is_some_and(|n| !n.starts_with('.') && n.ends_with(&format!(".{ext}")))
                        && is_own(p, Kind::File)
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Whether `p` is a `kind` itself (not a link to one).
fn is_own(p: &Path, kind: Kind) -> bool {
    fsutil::kind(p).ok().flatten() == Some(kind)
}

/// A cell of a column as text (numbers with 6 significant digits; null: empty).
fn cell(a: &dyn Array, i: usize) -> String {
    if a.is_null(i) {
        return String::new();
    }
    match a.data_type() {
        DataType::Utf8 => escape(a.as_string::<i32>().value(i)),
        DataType::Float64 => number(a.as_primitive::<Float64Type>().value(i)),
        DataType::UInt32 => a.as_primitive::<UInt32Type>().value(i).to_string(),
        DataType::UInt64 => a.as_primitive::<UInt64Type>().value(i).to_string(),
        DataType::Int32 => a.as_primitive::<Int32Type>().value(i).to_string(),
        DataType::Int64 => a.as_primitive::<Int64Type>().value(i).to_string(),
        DataType::Boolean => a.as_boolean().value(i).to_string(),
        t => escape(&format!("({t})")),
    }
}

/// `v` with 6 significant digits.
pub fn number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let e = v.abs().log10().floor() as i32;
    if (-3..5).contains(&e) {
        let s = format!("{:.*}", (5 - e).max(0) as usize, v);
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{v:.5e}")
    }
}

/// A row's `quality` (a text column of that name, as in `analysis_fits`) when it is not
/// "ok": the row is flagged, not a result.
fn flagged(b: &RecordBatch, i: usize) -> bool {
    b.column_by_name("quality")
        .filter(|c| matches!(c.data_type(), DataType::Utf8))
        .is_some_and(|c| !c.is_null(i) && c.as_string::<i32>().value(i) != "ok")
}

/// The rows of `batches` as an HTML table; a flagged row (see [`flagged`]) has the class
/// `flagged` (shaded) and its quality cell the class `q` (in red).
fn html_table(h: &mut String, batches: &[RecordBatch]) {
    let Some(first) = batches.first() else {
        return;
    };
    let n_flagged: usize = batches
        .iter()
        .map(|b| (0..b.num_rows()).filter(|&i| flagged(b, i)).count())
        .sum();
    h.push_str("<table>\n<tr>");
    for f in first.schema().fields() {
        let _ = write!(h, "<th>{}</th>", escape(f.name()));
    }
    h.push_str("</tr>\n");
    for b in batches {
        let schema = b.schema();
        for i in 0..b.num_rows() {
            let row_flagged = flagged(b, i);
            h.push_str(if row_flagged {
                "<tr class=\"flagged\">"
            } else {
                "<tr>"
            });
            for (field, col) in schema.fields().iter().zip(b.columns()) {
                let class = if row_flagged && field.name() == "quality" {
                    " class=\"q\""
                } else if matches!(col.data_type(), DataType::Utf8) {
                    ""
                } else {
                    " class=\"n\""
                };
                let _ = write!(h, "<td{class}>{}</td>", cell(col.as_ref(), i));
            }
            h.push_str("</tr>\n");
        }
    }
    h.push_str("</table>\n");
    if n_flagged > 0 {
        let _ = writeln!(
            h,
            "<p class=\"note\">{n_flagged} flagged rows (shaded; see their quality): not \
             results.</p>"
        );
    }
}

const B64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// Standard base64 with padding.
pub fn base64(data: &[u8]) -> String {
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(B64[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The section, if the campaign has an analysis directory; returns the figures embedded.
pub fn section(h: &mut String, c: &Campaign, notes: &mut Vec<String>) -> usize {
    let dir = c.analysis_dir();
    if !is_own(&dir, Kind::Dir) {
        return 0;
    }
    h.push_str("<h2 id=\"analysis\">Analysis</h2>\n");
    let _ = writeln!(
        h,
        "<p>What <code>granular analyze</code> wrote in {}.</p>",
        escape(&dir.display().to_string())
    );
    for path in files(&dir, "parquet") {
        let file = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let table = file.trim_end_matches(".parquet");
        match parquet_io::read_file(&path, table) {
            Ok(batches) => {
                let rows: usize = batches.iter().map(|b| b.num_rows()).sum();
                let _ = writeln!(
                    h,
                    "<h3 id=\"analysis-{t}\">{t}</h3>\n<p>{rows} rows.</p>",
                    t = escape(table)
                );
                if rows <= MAX_TABLE_ROWS {
                    html_table(h, &batches);
                }
            }
            Err(e) => {
                let n = format!("analysis table {file}: {e}");
                let _ = writeln!(h, "<p class=\"note\">{}</p>", escape(&n));
                notes.push(n);
            }
        }
    }
    let mut drawn = 0;
    for path in files(&dir.join("figures"), "svg") {
        let name = path
            .file_stem()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let bytes = match std::fs::metadata(&path) {
            Ok(m) if m.len() > MAX_FIGURE_BYTES => Err(format!("{} bytes", m.len())),
            _ => fsutil::open_regular(&path)
                .and_then(|mut f| {
                    let mut b = Vec::new();
                    std::io::Read::read_to_end(&mut f, &mut b).map(|_| b)
                })
                .map_err(|e| e.to_string()),
        };
        match bytes {
            Ok(b) => {
                let _ = writeln!(
                    h,
                    "<figure id=\"analysis-fig-{id}\">\n<img alt=\"{id}\" src=\"data:image/svg+xml;base64,{}\">\n<figcaption>{id}</figcaption>\n</figure>",
                    base64(&b),
                    id = escape(&name)
                );
                drawn += 1;
            }
            Err(e) => {
                let n = format!("analysis figure {name}: {e}");
                let _ = writeln!(h, "<p class=\"note\">{}</p>", escape(&n));
                notes.push(n);
            }
        }
    }
    drawn
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_as_rfc4648() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
        assert_eq!(base64(&[0xff, 0xfe, 0x00]), "//4A");
    }

    #[test]
    fn numbers_with_six_digits() {
        assert_eq!(number(1.5), "1.5");
        assert_eq!(number(1.2345678), "1.23457");
        assert_eq!(number(-0.00123456789), "-0.00123457");
        assert_eq!(number(123456.7), "1.23457e5");
        assert_eq!(number(0.0), "0");
        assert_eq!(number(f64::NAN), "NaN");
    }

    #[test]
    fn cells_escaped_and_nulls_empty() {
        let rows = [("<b>", Some(2.0)), ("x", None)];
        let b = crate::store::cols::table(&rows, |c| {
            vec![c.str("s", |r| r.0), c.opt_f64("v", |r| r.1)]
        });
        let mut h = String::new();
        html_table(&mut h, &[b]);
        assert!(h.contains("<th>s</th><th>v</th>"), "{h}");
        assert!(
            h.contains("<td>&lt;b&gt;</td><td class=\"n\">2</td>"),
            "{h}"
        );
        assert!(h.contains("<td>x</td><td class=\"n\"></td>"), "{h}");
        assert!(!h.contains("flagged"), "{h}");
    }

    /// A row whose `quality` is not "ok" is shaded (class `flagged`), its quality in red
    /// (class `q`), and the table says how many are flagged; an "ok" row is plain.
    #[test]
    fn flagged_fits_marked() {
        let rows = [
            (
                "C_R_exponent",
                2.1411,
                "poor_fit: chi2_r 10465 > 4.150 (p < 0.001 for 5 dof)",
            ),
            ("xi_2", 0.53, "ok"),
        ];
        let b = crate::store::cols::table(&rows, |c| {
            vec![
                c.str("quantity", |r| r.0),
                c.f64("value", |r| r.1),
                c.str("quality", |r| r.2),
            ]
        });
        let mut h = String::new();
        html_table(&mut h, &[b]);
        assert!(h.contains("1 flagged rows"), "{h}");
        assert!(
            h.contains(
                "<tr class=\"flagged\"><td>C_R_exponent</td><td class=\"n\">2.1411</td>\
                 <td class=\"q\">poor_fit: chi2_r 10465 &gt; 4.150 (p &lt; 0.001 for 5 dof)</td></tr>"
            ),
            "{h}"
        );
        assert!(
            h.contains("<tr><td>xi_2</td><td class=\"n\">0.53</td><td>ok</td></tr>"),
            "{h}"
        );
    }
}
