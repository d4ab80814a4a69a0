//! Key-expression intersection, to keep a channel's input key out of glrmon's own keys.
//!
//! glrmon publishes results on `glrmon/<channel>/<type>`, answers status queries on
//! `glrmon/@status/<instance>` and declares liveliness tokens on
//! `glrmon/@instances/<instance>` and `glrmon/@owners/<channel>/<instance>`. An input
//! key that intersects any of these would feed glrmon its own output: one bad payload
//! then produces an error record, which is itself a bad payload, forever.
//! [`check_input_key`] refuses such keys.
//!
//! [`intersects`] implements the Zenoh key-expression rules on canonical or
//! near-canonical expressions: chunks are separated by `/`; `*` matches exactly one
//! chunk, `**` zero or more chunks, `$*` any part of a chunk (possibly empty); a chunk
//! starting with `@` is verbatim: it matches only itself, never `*` or `**`.

/// The key expressions glrmon itself publishes, queries or declares on.
pub const OUTPUT_KEYS: [&str; 4] = [
    "glrmon/**",
    "glrmon/@status/*",
    "glrmon/@instances/*",
    "glrmon/@owners/**",
];

/// Longest accepted input key expression, in bytes.
pub const MAX_KEY_LEN: usize = 1024;

/// Checks a channel's input key expression: non-empty, well formed enough to reason
/// about (no empty chunk, no `?` or `#`), and disjoint from every key in [`OUTPUT_KEYS`].
///
/// # Errors
/// Why the key is refused, as a sentence that follows the field's path.
///
/// # Examples
///
/// ```
/// use glrmon_spec::keys::check_input_key;
///
/// assert!(check_input_key("plant/pump3").is_ok());
/// assert!(check_input_key("glrmon/**").is_err());
/// assert!(check_input_key("**").is_err());
/// assert!(check_input_key("*/pump3/*").is_err());
/// ```
pub fn check_input_key(key: &str) -> Result<(), String> {
    if key.is_empty() {
        return Err("is empty: give a key expression such as \"plant/pump3\"".into());
    }
    if key.len() > MAX_KEY_LEN {
        return Err(format!("has {} bytes: at most {MAX_KEY_LEN}", key.len()));
    }
    if key.split('/').any(str::is_empty) {
        return Err(format!(
            "\"{key}\" has an empty chunk (a leading, trailing or doubled '/')"
        ));
    }
    if let Some(c) = key
        .chars()
        .find(|c| matches!(c, '?' | '#') || c.is_whitespace() || c.is_control())
    {
        return Err(format!(
            "\"{}\" contains {c:?}, which a key expression cannot hold",
            key.escape_debug()
        ));
    }
    if let Some(own) = OUTPUT_KEYS.iter().find(|own| intersects(key, own)) {
        return Err(format!(
            "\"{key}\" intersects glrmon's own key space {own}: the channel would read \
             glrmon's results (or status) as its input, and every bad payload would feed \
             an error record back to it; use keys outside glrmon/** such as \"plant/…\""
        ));
    }
    Ok(())
}

/// Whether two key expressions can match a common key.
///
/// # Examples
///
/// ```
/// use glrmon_spec::keys::intersects;
///
/// assert!(intersects("glrmon/**", "glrmon/pump3/alarm"));
/// assert!(intersects("a/*/c", "a/b$*/c"));
/// assert!(!intersects("plant/**", "glrmon/**"));
/// assert!(!intersects("glrmon/**", "glrmon/@status/x"));
/// ```
#[must_use]
pub fn intersects(a: &str, b: &str) -> bool {
    let a: Vec<&str> = a.split('/').collect();
    let b: Vec<&str> = b.split('/').collect();
    // memo[i][j]: whether a[i..] and b[j..] intersect, once known.
    let mut memo = vec![vec![None; b.len() + 1]; a.len() + 1];
    chunks(&a, &b, 0, 0, &mut memo)
}

fn verbatim(chunk: &str) -> bool {
    chunk.starts_with('@')
}

fn chunks(a: &[&str], b: &[&str], i: usize, j: usize, memo: &mut [Vec<Option<bool>>]) -> bool {
    if let Some(known) = memo[i][j] {
        return known;
    }
    let result = match (a.get(i), b.get(j)) {
        (None, None) => true,
        // `**` matches nothing more, or swallows the other's next chunk (unless verbatim).
        (Some(&"**"), _) => {
            chunks(a, b, i + 1, j, memo)
                || (j < b.len() && !verbatim(b[j]) && chunks(a, b, i, j + 1, memo))
        }
        (_, Some(&"**")) => {
            chunks(a, b, i, j + 1, memo)
                || (i < a.len() && !verbatim(a[i]) && chunks(a, b, i + 1, j, memo))
        }
        (Some(x), Some(y)) => chunk(x, y) && chunks(a, b, i + 1, j + 1, memo),
        _ => false,
    };
    memo[i][j] = Some(result);
    result
}

/// Whether two chunks can match a common chunk.
fn chunk(x: &str, y: &str) -> bool {
    if verbatim(x) || verbatim(y) {
        return x == y;
    }
    if x == "*" || y == "*" {
        return true;
    }
    let x = pieces(x);
    let y = pieces(y);
    let mut memo = vec![vec![None; y.len() + 1]; x.len() + 1];
    globs(&x, &y, 0, 0, &mut memo)
}

#[derive(Clone, Copy, PartialEq)]
enum Piece {
    Char(char),
    Any,
}

fn pieces(chunk: &str) -> Vec<Piece> {
    let mut out = Vec::new();
    let mut rest = chunk;
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix("$*") {
            out.push(Piece::Any);
            rest = r;
        } else {
            let c = rest.chars().next().unwrap_or_default();
            out.push(Piece::Char(c));
            rest = &rest[c.len_utf8()..];
        }
    }
    out
}

/// Whether two patterns of characters and `$*` can match a common string.
fn globs(x: &[Piece], y: &[Piece], i: usize, j: usize, memo: &mut [Vec<Option<bool>>]) -> bool {
    if let Some(known) = memo[i][j] {
        return known;
    }
    let result = match (x.get(i), y.get(j)) {
        (None, None) => true,
        (Some(Piece::Any), _) => {
            globs(x, y, i + 1, j, memo) || (j < y.len() && globs(x, y, i, j + 1, memo))
        }
        (_, Some(Piece::Any)) => {
            globs(x, y, i, j + 1, memo) || (i < x.len() && globs(x, y, i + 1, j, memo))
        }
        (Some(Piece::Char(a)), Some(Piece::Char(b))) => a == b && globs(x, y, i + 1, j + 1, memo),
        _ => false,
    };
    memo[i][j] = Some(result);
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intersection_follows_the_zenoh_rules() {
        let yes = [
            ("glrmon/**", "glrmon/pump3/alarm"),
            ("**", "glrmon/pump3/alarm"),
            ("*/pump3/*", "glrmon/**"),
            ("glrmon/*/stat", "glrmon/**"),
            ("glr$*/**", "glrmon/**"),
            ("$*mon/x", "glrmon/**"),
            ("glrmon/@status/*", "glrmon/@status/a"),
            ("**/@status/*", "glrmon/@status/*"),
            ("a/**/b", "a/b"),
            ("a/**/b", "a/x/y/b"),
            ("a/$*b$*", "a/cbd"),
            ("**", "**"),
            ("a", "a"),
        ];
        let no = [
            ("plant/**", "glrmon/**"),
            ("glrmon", "glrmon/**/x"),
            ("glrmon/**", "glrmon/@status/*"),
            ("**", "glrmon/@status/*"),
            ("*/*/*", "glrmon/@status/*"),
            ("glrmonx/**", "glrmon/**"),
            ("a/$*b", "a/c"),
            ("a/b", "a/b/c"),
            ("plant/glrmon/**", "glrmon/**"),
        ];
        for (a, b) in yes {
            assert!(intersects(a, b), "{a} ∩ {b}");
            assert!(intersects(b, a), "{b} ∩ {a}");
        }
        for (a, b) in no {
            assert!(!intersects(a, b), "{a} ∩ {b}");
            assert!(!intersects(b, a), "{b} ∩ {a}");
        }
    }

    #[test]
    fn input_keys_outside_glrmon_pass_and_the_others_name_the_space() {
        for ok in ["plant/pump3", "plant/**", "site/*/glrmon", "a/$*"] {
            assert_eq!(check_input_key(ok), Ok(()), "{ok}");
        }
        for bad in [
            "glrmon/**",
            "**",
            "*/x/*",
            "glrmon/@status/*",
            "**/@owners/**",
            "",
        ] {
            assert!(check_input_key(bad).is_err(), "{bad}");
        }
        let e = check_input_key("glrmon/**").unwrap_err();
        assert!(e.contains("glrmon/**"), "{e}");
    }
}
