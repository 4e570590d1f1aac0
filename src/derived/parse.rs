//! The text of a derived quantity before evalexpr sees it: references to run-table columns
//! (`temperature`, `dsmc_species.temperature`, `temperature[species=1]`) and reductions over
//! them (`mean(ref)`, ...) are cut out and replaced by generated variable names (`__q0`,
//! `__q1`, ...); integer literals become float literals (`2` -> `2.0`, so that `1/2` is 0.5,
//! not evalexpr's integer division); short function names become evalexpr's (`sqrt` ->
//! `math::sqrt`). The arithmetic itself is evalexpr's (`build_operator_tree`).

/// A reduction of a reference over all the run's selected rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reduction {
    Mean,
    Sum,
    Min,
    Max,
    First,
    Last,
    Slope,
    Count,
}

impl Reduction {
    pub fn of(name: &str) -> Option<Reduction> {
        Some(match name {
            "mean" => Reduction::Mean,
            "sum" => Reduction::Sum,
            "min" => Reduction::Min,
            "max" => Reduction::Max,
            "first" => Reduction::First,
            "last" => Reduction::Last,
            "slope" => Reduction::Slope,
            "count" => Reduction::Count,
            _ => return None,
        })
    }
    pub fn name(self) -> &'static str {
        match self {
            Reduction::Mean => "mean",
            Reduction::Sum => "sum",
            Reduction::Min => "min",
            Reduction::Max => "max",
            Reduction::First => "first",
            Reduction::Last => "last",
            Reduction::Slope => "slope",
            Reduction::Count => "count",
        }
    }
}

/// A selector's literal as written.
#[derive(Debug, Clone, PartialEq)]
pub enum Lit {
    /// A number's text (`1`, `-2.5`, `1e-3`).
    Num(String),
    Str(String),
}

/// A reference as written: `[table.]column[sel=lit, ...]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RefText {
    pub table: Option<String>,
    pub column: String,
    pub selectors: Vec<(String, Lit)>,
    /// The text as written (messages).
    pub text: String,
}

/// What a generated variable stands for.
#[derive(Debug, Clone, PartialEq)]
pub enum Piece {
    Ref(RefText),
    Reduce(Reduction, RefText),
}

/// The short names of evalexpr's math functions (`sqrt(x)` for `math::sqrt(x)`).
pub const ALIASES: &[&str] = &[
    "sqrt", "cbrt", "ln", "log", "log2", "log10", "exp", "exp2", "pow", "abs", "sin", "cos", "tan",
    "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh", "acosh", "atanh", "hypot",
];

/// evalexpr's own functions that a quantity may call (besides `math::<alias>`).
const EVALEXPR_FUNCTIONS: &[&str] = &["floor", "round", "ceil", "min", "max", "if"];

/// The name of the `i`-th generated variable.
pub fn var(i: usize) -> String {
    format!("__q{i}")
}

fn ident_start(c: char) -> bool {
    c.is_ascii_alphabetic() || c == '_'
}

fn ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_' || c == '.' || c == ':'
}

/// The index of the bracket closing the one at `open` (`(`/`)` or `[`/`]`), skipping quoted
/// strings.
fn closing(b: &[char], open: usize) -> Option<usize> {
    let (o, c) = (b[open], if b[open] == '(' { ')' } else { ']' });
    let mut depth = 0usize;
    let mut i = open;
    while i < b.len() {
        let ch = b[i];
        if ch == '"' || ch == '\'' {
            i += 1;
            while i < b.len() && b[i] != ch {
                i += 1;
            }
        } else if ch == o {
            depth += 1;
        } else if ch == c {
            depth -= 1;
            if depth == 0 {
                return Some(i);
            }
        }
        i += 1;
    }
    None
}

/// Whether `s` has a comma outside brackets and quotes.
fn top_level_comma(s: &[char]) -> bool {
    let mut depth = 0i32;
    let mut quote = None;
    for &c in s {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, '(' | '[') => depth += 1,
            (None, ')' | ']') => depth -= 1,
            (None, ',') if depth == 0 => return true,
            _ => {}
        }
    }
    false
}

/// `s` split at its top-level commas.
fn split_commas(s: &str) -> Vec<String> {
    let mut out = vec![String::new()];
    let mut quote = None;
    for c in s.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, ',') => {
                out.push(String::new());
                continue;
            }
            _ => {}
        }
        out.last_mut().expect("one").push(c);
    }
    out
}

/// A number literal's length at `i` (digits, fraction, exponent), and whether it is an
/// integer.
fn number_at(b: &[char], i: usize) -> (usize, bool) {
    let mut j = i;
    let mut integer = true;
    while j < b.len() && b[j].is_ascii_digit() {
        j += 1;
    }
    if j < b.len() && b[j] == '.' {
        integer = false;
        j += 1;
        while j < b.len() && b[j].is_ascii_digit() {
            j += 1;
        }
    }
    if j < b.len() && (b[j] == 'e' || b[j] == 'E') {
        let mut k = j + 1;
        if k < b.len() && (b[k] == '+' || b[k] == '-') {
            k += 1;
        }
        if k < b.len() && b[k].is_ascii_digit() {
            integer = false;
            j = k;
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
        }
    }
    (j - i, integer)
}

/// A selector's value: a quoted string or a number.
fn literal(s: &str) -> Result<Lit, String> {
    let s = s.trim();
    let q = s.chars().next();
    if matches!(q, Some('\'' | '"')) {
        let q = q.expect("some");
        if s.len() >= 2 && s.ends_with(q) {
            return Ok(Lit::Str(s[1..s.len() - 1].to_string()));
        }
        return Err(format!("unterminated string {s}"));
    }
    if !s.is_empty()
        && s.parse::<f64>().is_ok()
        && !s
            .chars()
            .any(|c| c.is_ascii_alphabetic() && c != 'e' && c != 'E')
    {
        return Ok(Lit::Num(s.to_string()));
    }
    Err(format!(
        "expected a number or a quoted string as a selector's value, got `{s}`"
    ))
}

/// `[table.]column[sel=lit, ...]`, the whole of `s` (trimmed).
pub fn reference(s: &str) -> Result<RefText, String> {
    let text = s.trim().to_string();
    let b: Vec<char> = text.chars().collect();
    if b.is_empty() || !ident_start(b[0]) {
        return Err(format!(
            "expected a column reference (`column`, `table.column`, `column[key=value]`), got `{text}`"
        ));
    }
    let mut i = 0;
    while i < b.len() && ident_char(b[i]) {
        i += 1;
    }
    let word: String = b[..i].iter().collect();
    let (table, column) = match word.split_once('.') {
        Some((t, c)) => (Some(t.to_string()), c.to_string()),
        None => (None, word.clone()),
    };
    let valid = |x: &str| {
        x.chars().next().is_some_and(ident_start)
            && x.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    if !valid(&column) || table.as_deref().is_some_and(|t| !valid(t)) {
        return Err(format!(
            "`{word}` is not a column reference: expected `column` or `table.column` (letters, digits, `_`)"
        ));
    }
    while i < b.len() && b[i].is_whitespace() {
        i += 1;
    }
    let mut selectors = Vec::new();
    if i < b.len() && b[i] == '[' {
        let Some(end) = closing(&b, i) else {
            return Err(format!("`{text}`: `[` without its `]`"));
        };
        let inner: String = b[i + 1..end].iter().collect();
        for part in split_commas(&inner) {
            if part.trim().is_empty() {
                return Err(format!("`{text}`: an empty selector"));
            }
            let Some((k, v)) = part.split_once('=') else {
                return Err(format!(
                    "`{text}`: selector `{}` is not `column=value`",
                    part.trim()
                ));
            };
            let v = v.strip_prefix('=').unwrap_or(v);
            let k = k.trim();
            if !valid(k) {
                return Err(format!("`{text}`: `{k}` is not a column name"));
            }
            selectors.push((
                k.to_string(),
                literal(v).map_err(|e| format!("`{text}`: {e}"))?,
            ));
        }
        i = end + 1;
    }
    if b[i..].iter().any(|c| !c.is_whitespace()) {
        return Err(format!(
            "expected a single column reference (`column`, `table.column`, `column[key=value]`), got `{text}`"
        ));
    }
    Ok(RefText {
        table,
        column,
        selectors,
        text,
    })
}

/// The text for evalexpr and its pieces (piece `i` is variable [`var`]`(i)`), or every
/// problem found.
pub fn rewrite(text: &str) -> Result<(String, Vec<Piece>), Vec<String>> {
    let b: Vec<char> = text.chars().collect();
    let mut out = String::new();
    let mut pieces = Vec::new();
    let mut errors = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == '"' {
            let mut j = i + 1;
            while j < b.len() && b[j] != '"' {
                j += if b[j] == '\\' { 2 } else { 1 };
            }
            let j = (j + 1).min(b.len());
            out.extend(&b[i..j]);
            i = j;
            continue;
        }
        if c.is_ascii_digit() || (c == '.' && b.get(i + 1).is_some_and(|d| d.is_ascii_digit())) {
            let (n, integer) = number_at(&b, i);
            out.extend(&b[i..i + n]);
            if integer && !b.get(i + n).is_some_and(|&d| ident_char(d)) {
                out.push_str(".0");
            }
            i += n;
            continue;
        }
        if !ident_start(c) {
            out.push(c);
            i += 1;
            continue;
        }
        let start = i;
        while i < b.len() && ident_char(b[i]) {
            i += 1;
        }
        let word: String = b[start..i].iter().collect();
        let mut j = i;
        while j < b.len() && b[j].is_whitespace() {
            j += 1;
        }
        match b.get(j) {
            Some('(') => {
                let reduction = Reduction::of(&word);
                let close = closing(&b, j);
                match (reduction, close) {
                    (Some(r), Some(k))
                        if !(matches!(r, Reduction::Min | Reduction::Max)
                            && top_level_comma(&b[j + 1..k])) =>
                    {
                        let arg: String = b[j + 1..k].iter().collect();
                        match reference(&arg) {
                            Ok(rt) => {
                                out.push_str(&var(pieces.len()));
                                pieces.push(Piece::Reduce(r, rt));
                            }
                            Err(e) => errors.push(format!(
                                "the argument of the reduction `{word}(...)` must be a single column reference: {e}"
                            )),
                        }
                        i = k + 1;
                    }
                    (Some(_), _) => out.push_str(&word),
                    (None, _) if ALIASES.contains(&word.as_str()) => {
                        out.push_str("math::");
                        out.push_str(&word);
                    }
                    (None, _)
                        if EVALEXPR_FUNCTIONS.contains(&word.as_str())
                            || word
                                .strip_prefix("math::")
                                .is_some_and(|f| ALIASES.contains(&f)) =>
                    {
                        out.push_str(&word)
                    }
                    (None, _) => {
                        let mut known: Vec<&str> = [
                            "mean", "sum", "min", "max", "first", "last", "slope", "count",
                        ]
                        .into_iter()
                        .chain(ALIASES.iter().copied())
                        .chain(["floor", "round", "ceil", "if"])
                        .collect();
                        known.sort_by_key(|k| (super::distance(k, &word), *k));
                        errors.push(format!(
                            "unknown function `{word}`: expected one of {} (nearest first)",
                            known.join(", ")
                        ));
                        out.push_str(&word);
                    }
                }
            }
            _ if word == "true" || word == "false" => out.push_str(&word),
            Some('[') => {
                let end = closing(&b, j).unwrap_or(b.len() - 1);
                let t: String = b[start..=end].iter().collect();
                match reference(&t) {
                    Ok(rt) => {
                        out.push_str(&var(pieces.len()));
                        pieces.push(Piece::Ref(rt));
                    }
                    Err(e) => errors.push(e),
                }
                i = end + 1;
            }
            _ => match reference(&word) {
                Ok(rt) => {
                    out.push_str(&var(pieces.len()));
                    pieces.push(Piece::Ref(rt));
                }
                Err(e) => errors.push(e),
            },
        }
    }
    if errors.is_empty() {
        Ok((out, pieces))
    } else {
        Err(errors)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_and_reductions_become_variables() {
        let (t, p) =
            rewrite("temperature[species=1] / dsmc_species.temperature[species = 0]").unwrap();
        assert_eq!(t, "__q0 / __q1");
        assert_eq!(p.len(), 2);
        let Piece::Ref(r) = &p[1] else { panic!() };
        assert_eq!(r.table.as_deref(), Some("dsmc_species"));
        assert_eq!(r.selectors, vec![("species".into(), Lit::Num("0".into()))]);
        let (t, p) = rewrite("slope(msd[species=0]) / 6 + sqrt(2) * 1e-3").unwrap();
        assert_eq!(t, "__q0 / 6.0 + math::sqrt(2.0) * 1e-3");
        assert!(matches!(&p[0], Piece::Reduce(Reduction::Slope, _)));
        let (t, _) = rewrite("density[kind='v', h=3] + max(1, 2)").unwrap();
        assert_eq!(t, "__q0 + max(1.0, 2.0)");
    }

    #[test]
    fn refusals() {
        let e = rewrite("mean(temperature * 2) + foo(1)").unwrap_err();
        assert_eq!(e.len(), 2, "{e:?}");
        assert!(e[0].contains("single column reference"), "{e:?}");
        assert!(e[1].contains("unknown function `foo`"), "{e:?}");
        assert!(rewrite("x[species]").is_err());
        assert!(rewrite("x[species=abc]").is_err());
    }
}
