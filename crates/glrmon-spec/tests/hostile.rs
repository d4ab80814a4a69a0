//! Hostile configurations: empty or ragged matrices, absurd sizes, input keys in
//! glrmon's own key space, unsafe instance names. Each must be refused with the path of
//! the field at fault — never a panic, an abort or a long computation.

mod common;
use common::{BASE, with};

/// The errors of `text`, which must be invalid; a panic fails the test with the text.
fn errors(text: &str) -> Vec<String> {
    let owned = text.to_owned();
    let result = std::panic::catch_unwind(move || glrmon_spec::parse(&owned));
    match result {
        Err(_) => panic!("validation panicked on:\n{text}"),
        Ok(Ok(_)) => panic!("expected errors for:\n{text}"),
        Ok(Err(e)) => e.errors.iter().map(ToString::to_string).collect(),
    }
}

fn assert_error(text: &str, expected: &str) {
    let errs = errors(text);
    assert!(
        errs.iter().any(|e| e.contains(expected)),
        "wanted «{expected}» in {errs:#?}\nfor:\n{text}"
    );
}

/// Every empty, ragged or mis-shaped matrix is an error naming the matrix.
#[test]
fn empty_and_ragged_matrices_are_errors_naming_the_field() {
    let cases: &[(&str, &str, &str)] = &[
        ("H = [[1.0, 0.0]]", "H = []", "model.H"),
        ("H = [[1.0, 0.0]]", "H = [[]]", "model.H"),
        ("H = [[1.0, 0.0]]", "H = [[1.0, 0.0], [1.0]]", "model.H"),
        ("H = [[1.0, 0.0]]", "H = [[1.0]]", "model.F"),
        ("H = [[1.0, 0.0]]", "H = 1.0", "model.H"),
        ("H = [[1.0, 0.0]]", "H = { base = [] }", "model.H"),
        (
            "H = [[1.0, 0.0]]",
            "H = { base = [[1.0, 0.0]], p0 = [] }",
            "model.H.p0",
        ),
        (
            "H = [[1.0, 0.0]]",
            "H = { base = [[1.0, 0.0]], p0 = [[1.0]] }",
            "model.H.p0",
        ),
        ("F = [[0.5, 1.0], [0.0, 0.8]]", "F = []", "model.F"),
        ("F = [[0.5, 1.0], [0.0, 0.8]]", "F = [[]]", "model.F"),
        (
            "F = [[0.5, 1.0], [0.0, 0.8]]",
            "F = [[0.5, 1.0], [0.0]]",
            "model.F",
        ),
        (
            "F = [[0.5, 1.0], [0.0, 0.8]]",
            "F = [[0.5], [0.0]]",
            "model.F",
        ),
        (
            "F = [[0.5, 1.0], [0.0, 0.8]]",
            "F = { base = [[0.5, 1.0], [0.0, 0.8]], p0 = [[]] }",
            "model.F.p0",
        ),
        ("G = [[0.0], [1.0]]", "G = []", "model.G"),
        ("G = [[0.0], [1.0]]", "G = [[]]", "model.G"),
        ("G = [[0.0], [1.0]]", "G = [[0.0], []]", "model.G"),
        ("G = [[0.0], [1.0]]", "G = [[0.0, 1.0]]", "model.G"),
        ("Q = 0.01", "Q = []", "model.Q"),
        ("Q = 0.01", "Q = [[]]", "model.Q"),
        ("Q = 0.01", "Q = [[0.01, 0.0], [0.0]]", "model.Q"),
        ("R = 0.04", "R = []", "model.R"),
        ("R = 0.04", "R = [[]]", "model.R"),
        ("R = 0.04", "R = [[0.04, 0.0], [0.0, 0.04]]", "model.R"),
        ("R = 0.04", "R = 0.04\nP0 = []", "model.P0"),
        ("R = 0.04", "R = 0.04\nP0 = [[]]", "model.P0"),
        ("R = 0.04", "R = 0.04\nP0 = [[1.0, 0.0], [0.0]]", "model.P0"),
        ("R = 0.04", "R = 0.04\nP0 = [[1.0]]", "model.P0"),
        ("R = 0.04", "R = 0.04\nJ = []", "model.J"),
        ("R = 0.04", "R = 0.04\nJ = [[]]", "model.J"),
        ("R = 0.04", "R = 0.04\nJ = [[1.0, 2.0]]", "model.J"),
        ("R = 0.04", "R = 0.04\nE = []", "model.E"),
        ("R = 0.04", "R = 0.04\nE = [[]]", "model.E"),
        ("R = 0.04", "R = 0.04\nE = [[1.0], []]", "model.E"),
        ("R = 0.04", "R = 0.04\nE = [[1.0]]", "model.E"),
        ("R = 0.04", "R = 0.04\nS = []", "model.S"),
        ("R = 0.04", "R = 0.04\nS = [[]]", "model.S"),
        ("R = 0.04", "R = 0.04\nS = [[0.0], []]", "model.S"),
        ("R = 0.04", "R = 0.04\nx0 = []", "model.x0"),
    ];
    for (from, to, field) in cases {
        assert_error(&with(from, to), field);
    }
    // Two at once, and H = [] with an E, which once reached nalgebra and panicked.
    assert_error(
        &with("H = [[1.0, 0.0]]", "H = []\nE = [[1.0], [0.0]]"),
        "model.H",
    );
    assert_error(
        &with("F = [[0.5, 1.0], [0.0, 0.8]]", "F = []").replace("H = [[1.0, 0.0]]", "H = []"),
        "model.",
    );
}

/// A dictionary of `m` custom faults f0…f{m−1} on the first state.
fn many_faults(m: usize) -> String {
    let mut text = BASE.to_owned();
    for i in 0..m {
        text.push_str(&format!(
            "\n[[channels.faults]]\nname = \"f{i}\"\npsi = [{}.0, 1.0]\n",
            i + 1
        ));
    }
    text
}

/// Sizes that once overflowed or aborted (2⁶³−1, 1e9, a history of 1e12) and every
/// other size are refused with the field's path; a channel over the memory budget gets
/// the estimate in the message.
#[test]
fn every_size_has_an_upper_bound_named_by_its_field() {
    let w = "window = 50";
    assert_error(
        &with(w, "window = 9223372036854775807"),
        "glr.window: w = 9223372036854775807 is more than 100000",
    );
    assert_error(
        &with(w, "window = 1000000000"),
        "glr.window: w = 1000000000 is more than 100000",
    );
    let history =
        format!("{BASE}\n[channels.diagnosis]\nenabled = true\nhistory = 1000000000000\n");
    assert_error(
        &history,
        "diagnosis.history: 1000000000000 samples is more than 1000000",
    );
    let span = format!("{BASE}\n[channels.diagnosis]\nspan = 1000000000000\n");
    assert_error(&span, "diagnosis.span");
    let path = format!("{BASE}\n[channels.diagnosis.lasso]\npath_points = 1000000000\n");
    assert_error(&path, "diagnosis.lasso.path_points");
    assert_error(
        &with(w, "window = 50\nmax_gap = 1000000000000"),
        "glr.max_gap",
    );
    assert_error(
        &with(w, "window = 50\nmax_reorder = 1000000000000"),
        "glr.max_reorder",
    );
    assert_error(
        &with(w, "window = 50\nwarm_up = 100000000000"),
        "glr.warm_up",
    );
    assert_error(
        &with("name = \"pump3\"", "name = \"pump3\"\nsignals = 100000000"),
        "signals is 100000000: at most 1024",
    );
    assert_error(
        &with(
            "F = [[0.5, 1.0], [0.0, 0.8]]",
            "F = { base = [[0.5, 1.0], [0.0, 0.8]], p18446744073709551615 = [[0.0, 0.0], [0.0, 0.0]] }",
        ),
        "model.F.p18446744073709551615",
    );
    let consistency = format!("{BASE}\n[channels.consistency]\nwindow = 1000000000000\n");
    assert_error(&consistency, "consistency.window");
    for (field, value) in [
        ("workers", "100000"),
        ("worker_queue", "1000000000000"),
        ("output_queue", "1000000000000"),
        ("max_payload_bytes", "1000000000000"),
    ] {
        assert_error(
            &format!("[daemon]\n{field} = {value}\n{BASE}"),
            &format!("daemon.{field}"),
        );
    }
    assert_error(
        &format!("[recording]\nqueue = 1000000000000\n{BASE}"),
        "recording.queue",
    );
    assert_error(
        &format!("[recording.capture]\nbefore_seconds = 1e9\nafter_seconds = 1.0\n{BASE}"),
        "recording.capture.before_seconds",
    );
    // n = 129 states.
    let n = 129;
    let rows: Vec<String> = (0..n)
        .map(|i| {
            format!(
                "[{}]",
                (0..n)
                    .map(|j| if i == j { "0.5" } else { "0.0" })
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
        .collect();
    let h = format!(
        "[[{}]]",
        (0..n)
            .map(|j| if j == 0 { "1.0" } else { "0.0" })
            .collect::<Vec<_>>()
            .join(", ")
    );
    let big = with(
        "F = [[0.5, 1.0], [0.0, 0.8]]",
        &format!("F = [{}]", rows.join(", ")),
    )
    .replace("H = [[1.0, 0.0]]", &format!("H = {h}"));
    assert_error(&big, "model.F is 129×129: at most 128 states");
    // The memory budget: w = 100000 is within its own limit, but with 27 faults the
    // window bank needs 8·10⁵·(3·2·27 + 2·27 + 2·27² + 6·27 + 7) B = 1.4 GiB, and the
    // diagnosis ring of 2w samples 0.2 GiB more.
    let heavy = many_faults(25).replace("window = 50", "window = 100000");
    assert_error(
        &heavy,
        "glr.window: makes the channel need about 1.6 GiB (window bank 1.4 GiB",
    );
    assert_error(&heavy, "more than the budget of 1.0 GiB per channel");
    // The same dictionary with w = 10000 fits.
    let fits = many_faults(25).replace("window = 50", "window = 10000");
    assert!(glrmon_spec::parse(&fits).is_ok());
    // w = 100000 alone fits too (34 MiB of window bank, 77 MiB of diagnosis ring).
    assert!(glrmon_spec::parse(&with(w, "window = 100000")).is_ok());
}

/// An input key that intersects glrmon's own output or status keys.
#[test]
fn input_keys_in_glrmons_own_key_space_are_refused() {
    for key in [
        "glrmon/**",
        "**",
        "glrmon/pump3/*",
        "*/pump3/alarm",
        "glrmon/@status/*",
        "**/@instances/*",
        "gl$*/**",
    ] {
        assert_error(
            &with(
                "name = \"pump3\"",
                &format!("name = \"pump3\"\nkey = \"{key}\""),
            ),
            "channels[0] \"pump3\": key: ",
        );
    }
    assert_error(
        &with("name = \"pump3\"", "name = \"pump3\"\nkey = \"\""),
        "key is empty",
    );
    for key in ["plant/pump3", "plant/**", "site/*/glrmon/x"] {
        let text = with(
            "name = \"pump3\"",
            &format!("name = \"pump3\"\nkey = \"{key}\""),
        );
        assert!(glrmon_spec::parse(&text).is_ok(), "{key}");
    }
}

/// Instance names are one safe key chunk.
#[test]
fn instance_names_are_one_safe_key_chunk() {
    for bad in ["", "a/b/**", "*", "a b", "@x", "é"] {
        assert_error(
            &format!("[daemon]\ninstance = \"{bad}\"\n{BASE}"),
            "daemon.instance",
        );
    }
    let long = "x".repeat(65);
    assert_error(
        &format!("[daemon]\ninstance = \"{long}\"\n{BASE}"),
        "daemon.instance has 65 characters",
    );
    for good in ["plant-a.01", "glrmon_7", &"x".repeat(64)] {
        assert!(glrmon_spec::parse(&format!("[daemon]\ninstance = \"{good}\"\n{BASE}")).is_ok());
    }
}

mod shapes {
    use proptest::prelude::*;

    /// A matrix as written: up to 3 rows of up to 3 entries each (ragged, empty, or a
    /// scalar when `None`).
    fn matrix() -> impl Strategy<Value = Option<Vec<Vec<f64>>>> {
        proptest::option::of(proptest::collection::vec(
            proptest::collection::vec(-2.0_f64..2.0, 0..4),
            0..4,
        ))
    }

    fn toml(name: &str, m: &Option<Vec<Vec<f64>>>, scalar: &str) -> String {
        match m {
            None => format!("{name} = {scalar}\n"),
            Some(rows) => {
                let rows: Vec<String> = rows
                    .iter()
                    .map(|r| {
                        let r: Vec<String> = r.iter().map(|x| format!("{x:?}")).collect();
                        format!("[{}]", r.join(", "))
                    })
                    .collect();
                format!("{name} = [{}]\n", rows.join(", "))
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        /// Exhaustively over small shapes: whatever the shapes of F, G, H, J, Q,
        /// R, P0, E and S, validation returns (a configuration or errors), never panics.
        #[test]
        fn any_matrix_shapes_are_validated_without_panicking(
            f in matrix(), g in matrix(), h in matrix(), j in matrix(), q in matrix(),
            r in matrix(), p0 in matrix(), e in matrix(), s in matrix(),
            with in proptest::collection::vec(any::<bool>(), 5),
        ) {
            let mut text = String::from("[[channels]]\nname = \"c\"\n\n[channels.model]\n");
            text.push_str(&toml("F", &f, "0.5"));
            text.push_str(&toml("H", &h, "1.0"));
            text.push_str(&toml("Q", &q, "0.01"));
            text.push_str(&toml("R", &r, "0.04"));
            for (present, name, m, scalar) in [
                (with[0], "G", &g, "1.0"),
                (with[1], "J", &j, "0.0"),
                (with[2], "P0", &p0, "1.0"),
                (with[3], "E", &e, "1.0"),
                (with[4], "S", &s, "0.0"),
            ] {
                if present {
                    text.push_str(&toml(name, m, scalar));
                }
            }
            text.push_str("\n[[channels.faults]]\nkind = \"all_sensors\"\n");
            let _ = glrmon_spec::parse(&text);
        }
    }
}

/// A huge F (1e300 with three states) once made validation run forever: the powers
/// H F^i of the observability check overflowed, and the SVD of a matrix with infinite
/// entries does not terminate. Validation now returns within seconds, and says it
/// could not check observability only when even scaled blocks overflow.
#[test]
fn a_huge_f_is_validated_in_bounded_time() {
    for scale in ["1e300", "1e308"] {
        let text = format!(
            "[[channels]]\nname = \"c\"\n[channels.model]\n\
             F = [[{scale}, 1.0, 0.0], [0.0, {scale}, 1.0], [0.0, 0.0, {scale}]]\n\
             H = [[1.0, 0.0, 0.0]]\nQ = 0.01\nR = 0.04\n\
             [[channels.faults]]\nkind = \"all_sensors\"\n"
        );
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(glrmon_spec::parse(&text).map(|c| c.warnings.len()));
        });
        let result = rx.recv_timeout(std::time::Duration::from_secs(60));
        assert!(
            result.is_ok(),
            "F = {scale}: validation did not return in 60 s"
        );
    }
}
