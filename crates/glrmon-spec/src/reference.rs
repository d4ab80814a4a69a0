//! docs/CONFIG.md, generated: hand-written prose around key tables taken from the JSON
//! Schema ([`crate::json_schema`], so from the configuration types' doc comments and
//! defaults), with examples from the template of `glrmon config init` and the limits of
//! [`crate::limits`]. `make config-doc` writes it; a test fails when the file differs.

use std::fmt::Write as _;

use serde_json::Value;

use crate::limits;

/// The sections of a file, in the order of the reference: (TOML header, schema
/// definition, what it is for).
const SECTIONS: [(&str, &str); 27] = [
    ("[zenoh]", "ZenohSpec"),
    ("[daemon]", "DaemonSpec"),
    ("[recording]", "RecordingSpec"),
    ("[recording.capture]", "CaptureSpec"),
    ("[[channels]]", "ChannelSpec"),
    ("[channels.cdr]", "CdrSpec"),
    ("[channels.raw]", "RawSpec"),
    ("[channels.tags]", "TagsSpec"),
    ("[channels.tags.keys.<signal>]", "TagFieldsSpec"),
    ("[channels.model]", "ModelSpec"),
    ("[channels.scaling]", "ScalingSpec"),
    ("[channels.columns]", "ColumnsSpec"),
    ("[[channels.faults]]", "FaultSpec"),
    ("[channels.glr]", "GlrSpec"),
    ("[[channels.glr.groups]]", "GroupSpec"),
    ("[channels.glr.calibrated]", "CalibratedSpec"),
    ("[channels.simulation]", "SimulationSpec"),
    ("[channels.simulation.controller]", "ControllerSpec"),
    ("[channels.diagnosis]", "DiagnosisSpec"),
    ("[channels.diagnosis.lasso]", "LassoSpec"),
    ("[channels.consistency]", "ConsistencySpec"),
    ("[channels.cusum]", "CusumSpec"),
    ("[channels.parity]", "ParitySpec"),
    ("[channels.observer]", "ObserverSpec"),
    ("[channels.rls]", "RlsSpec"),
    ("[channels.kernel]", "KernelSpec"),
    ("[[channels.kernel.candidates]]", "KernelCandidateSpec"),
];

/// The text of docs/CONFIG.md.
#[must_use]
pub fn config_reference() -> String {
    let schema: Value = serde_json::from_str(&crate::json_schema()).unwrap_or(Value::Null);
    let template = crate::template::config_template("tank");
    let mut out = String::new();
    out.push_str(INTRO);
    out.push_str("\n## Keys\n\n");
    out.push_str(
        "Every table below is generated from the configuration types (their doc comments \
         and defaults, through the JSON Schema); the examples are the values of \
         `glrmon config init`'s template. *required* keys must be given; the others may \
         be left out.\n",
    );
    for (header, def) in SECTIONS {
        let Some(d) = schema["definitions"].get(def) else {
            continue;
        };
        let _ = write!(out, "\n### `{header}`\n\n");
        if let Some(text) = d["description"].as_str() {
            let _ = writeln!(out, "{}\n", escape(text));
        }
        out.push_str("| key | type | default | meaning | example |\n|---|---|---|---|---|\n");
        let required: Vec<&str> = d["required"]
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default();
        let Some(props) = d["properties"].as_object() else {
            continue;
        };
        let mut keys: Vec<&String> = props.keys().collect();
        // Required keys first, then in the template's order.
        keys.sort_by_key(|k| {
            (
                !required.contains(&k.as_str()),
                example(&template, header, k).map_or(usize::MAX, |(at, _)| at),
            )
        });
        for key in keys {
            let p = &props[key];
            let description = p["description"].as_str().unwrap_or("");
            let (meaning, default_text) = split_default(description);
            let default = if required.contains(&key.as_str()) {
                "*required*".to_owned()
            } else if let Some(v) = p.get("default") {
                format!("`{}`", json_as_toml(v))
            } else if let Some(text) = default_text {
                text
            } else if type_of(p) == "table" {
                "the defaults of its keys".to_owned()
            } else if meaning.contains("default") {
                "see meaning".to_owned()
            } else {
                "none".to_owned()
            };
            let ex = example(&template, header, key)
                .map_or_else(String::new, |(_, v)| format!("`{}`", v.replace('|', "\\|")));
            let _ = writeln!(
                out,
                "| `{key}` | {} | {} | {} | {ex} |",
                type_of(p),
                escape(&default),
                escape(&meaning)
            );
        }
    }
    out.push_str(FAULTS);
    out.push_str(MODEL);
    out.push_str(EXPRESSIONS);
    out.push_str(&limits_section());
    out
}

/// `|` would end a table cell.
fn escape(text: &str) -> String {
    text.replace('|', "\\|")
}

/// The description without its `Default …` sentence, and that default.
fn split_default(description: &str) -> (String, Option<String>) {
    let Some(at) = description.find("Default") else {
        return (description.to_owned(), None);
    };
    let sentence = &description[at..];
    // The sentence ends at the first ". " or at the end.
    let end = sentence.find(". ").map_or(sentence.len(), |i| i + 1);
    let default = sentence[..end]
        .trim_start_matches("Default")
        .trim_start_matches(':')
        .trim()
        .trim_end_matches('.')
        .to_owned();
    let meaning = format!(
        "{} {}",
        description[..at].trim_end(),
        sentence[end..].trim_start()
    )
    .trim()
    .to_owned();
    (meaning, Some(default))
}

/// A JSON default as it is written in TOML.
fn json_as_toml(v: &Value) -> String {
    match v {
        Value::String(s) => format!("\"{s}\""),
        Value::Array(a) => {
            let items: Vec<String> = a.iter().map(json_as_toml).collect();
            format!("[{}]", items.join(", "))
        }
        Value::Object(o) if o.is_empty() => "{}".to_owned(),
        other => other.to_string(),
    }
}

/// A short type for the table: `integer`, `number`, `string`, `matrix`, `array of …`,
/// `one of "a", "b"`, `table`.
fn type_of(p: &Value) -> String {
    if let Some(r) = p["$ref"].as_str() {
        let name = r.trim_start_matches("#/definitions/");
        return match name {
            "Matrix" => "matrix".to_owned(),
            "Entry" => "number or expression".to_owned(),
            "WarmUp" => "integer or `\"window\"`".to_owned(),
            _ => "table".to_owned(),
        };
    }
    for combinator in ["allOf", "anyOf"] {
        if let Some(alternatives) = p[combinator].as_array() {
            let types: Vec<String> = alternatives
                .iter()
                .filter(|a| a["type"] != "null")
                .map(type_of)
                .collect();
            return types.join(" or ");
        }
    }
    if let Some(values) = p["enum"].as_array() {
        let v: Vec<String> = values.iter().map(|v| format!("`{v}`")).collect();
        return format!("one of {}", v.join(", "));
    }
    let kind = match &p["type"] {
        Value::String(t) => t.clone(),
        Value::Array(ts) => ts
            .iter()
            .filter_map(Value::as_str)
            .find(|t| *t != "null")
            .unwrap_or("")
            .to_owned(),
        _ => String::new(),
    };
    match kind.as_str() {
        "array" => match &p["items"] {
            Value::Array(tuple) => format!("array of {} numbers", tuple.len()),
            items => format!("array of {}", plural(&type_of(items))),
        },
        "object" if p.get("additionalProperties").is_some_and(Value::is_object) => {
            format!("table of {}", plural(&type_of(&p["additionalProperties"])))
        }
        "object" => "table".to_owned(),
        "boolean" => "boolean".to_owned(),
        other => other.to_owned(),
    }
}

fn plural(t: &str) -> String {
    match t {
        "number" | "integer" | "string" | "matrix" | "table" | "boolean" => format!("{t}s"),
        "number or expression" => "numbers or expressions".to_owned(),
        other => other.to_owned(),
    }
}

/// The value of `key` in the template's `header` section (set or commented out), with
/// its position in the template (for ordering).
fn example(template: &str, header: &str, key: &str) -> Option<(usize, String)> {
    let mut current = "";
    for (n, line) in template.lines().enumerate() {
        let bare = line.trim_start_matches('#').trim();
        if bare.starts_with('[') {
            current = bare.split_whitespace().next().unwrap_or("");
            continue;
        }
        if current != header {
            continue;
        }
        let Some((k, v)) = bare.split_once(" = ") else {
            continue;
        };
        if k.trim() == key {
            let value = v.split("  #").next().unwrap_or(v).trim().to_owned();
            return Some((n, value));
        }
    }
    None
}

fn limits_section() -> String {
    let rows: [(&str, String, &str); 18] = [
        (
            "states n (rows of F)",
            limits::MAX_STATES.to_string(),
            "MAX_STATES",
        ),
        (
            "outputs p (rows of H)",
            limits::MAX_OUTPUTS.to_string(),
            "MAX_OUTPUTS",
        ),
        (
            "known inputs l (columns of G, J)",
            limits::MAX_INPUTS.to_string(),
            "MAX_INPUTS",
        ),
        (
            "scheduling signals q (`signals`, `p<i>`)",
            limits::MAX_SIGNALS.to_string(),
            "MAX_SIGNALS",
        ),
        (
            "faults m (after the shortcuts)",
            limits::MAX_FAULTS.to_string(),
            "MAX_FAULTS",
        ),
        (
            "rows or columns of a matrix as written",
            limits::MAX_MATRIX_SIDE.to_string(),
            "MAX_MATRIX_SIDE",
        ),
        ("`glr.window`", limits::MAX_WINDOW.to_string(), "MAX_WINDOW"),
        ("`glr.max_gap`", limits::MAX_GAP.to_string(), "MAX_GAP"),
        ("`glr.settle`", limits::MAX_SETTLE.to_string(), "MAX_SETTLE"),
        (
            "`glr.max_reorder`",
            limits::MAX_REORDER.to_string(),
            "MAX_REORDER",
        ),
        (
            "`glr.warm_up` (samples)",
            limits::MAX_WARM_UP.to_string(),
            "MAX_WARM_UP",
        ),
        (
            "`diagnosis.history`, `diagnosis.span`",
            limits::MAX_HISTORY.to_string(),
            "MAX_HISTORY",
        ),
        (
            "`diagnosis.lasso.path_points`",
            limits::MAX_PATH_POINTS.to_string(),
            "MAX_PATH_POINTS",
        ),
        (
            "`consistency.window`",
            limits::MAX_CONSISTENCY_WINDOW.to_string(),
            "MAX_CONSISTENCY_WINDOW",
        ),
        (
            "`daemon.workers`",
            limits::MAX_WORKERS.to_string(),
            "MAX_WORKERS",
        ),
        (
            "`daemon.worker_queue`, `daemon.output_queue`, `recording.queue`",
            limits::MAX_QUEUE.to_string(),
            "MAX_QUEUE",
        ),
        (
            "`daemon.max_payload_bytes`",
            limits::MAX_PAYLOAD_BYTES.to_string(),
            "MAX_PAYLOAD_BYTES",
        ),
        (
            "`recording.capture.before_seconds`, `after_seconds`",
            limits::MAX_CAPTURE_SECONDS.to_string(),
            "MAX_CAPTURE_SECONDS",
        ),
    ];
    let mut out = String::from(
        "\n## Limits\n\nA configuration beyond these is refused by `glrmon validate` (and by \
         every command that loads it) with the field and the limit; they bound the memory \
         and time any file can ask for (`glrmon_spec::limits`).\n\n\
         | what | at most | constant |\n|---|---|---|\n",
    );
    for (what, value, name) in rows {
        let _ = writeln!(out, "| {what} | {value} | `{name}` |");
    }
    let _ = writeln!(
        out,
        "| memory of one channel (window bank, diagnosis ring, matrices) | {} | `CHANNEL_MEMORY_BUDGET` |",
        limits::human_bytes(limits::CHANNEL_MEMORY_BUDGET)
    );
    let _ = writeln!(
        out,
        "| length of an expression | {} bytes | `expr::MAX_LEN` |\n\
         | nesting of an expression | {} levels | `expr::MAX_DEPTH` |\n\
         | lag of an expression (`u0[-n]`) | {} samples | `expr::MAX_LAG` |",
        crate::expr::MAX_LEN,
        crate::expr::MAX_DEPTH,
        crate::expr::MAX_LAG
    );
    out
}

const INTRO: &str = r#"<!-- Generated by `make config-doc` (crates/glrmon-spec/src/reference.rs) from the
configuration types: edit those, not this file. A test fails when the two differ. -->

# Configuration reference

A glrmon configuration is one TOML file describing a deployment: the Zenoh session, the
recording, the daemon, and the monitored channels, each with its state-space model, its
fault dictionary and its GLR settings. The file is strict: an unknown key is an error
(with the closest known key suggested), and every error names the file, line and column
of the key and the path of the field, e.g.

```text
plant.toml:22:1: channels[0] "pump3": glr.window: w = 0 must be at least 2
plant.toml:14:1: channels[0] "pump3": faults[0].kind: "actuator_bais" is not one of custom, actuator_bias, actuator_gain, sensor_bias, sensor_drift, all_sensors, all_actuators; did you mean "actuator_bias"?
```

## Getting started

```sh
glrmon config init --channel tank --output glrmon.toml   # a commented template
glrmon validate --config glrmon.toml                          # errors, or a summary per channel
glrmon config schema > glrmon.schema.json               # the JSON Schema, for editors
```

The template has one channel with a small model (2 states, 1 input, 2 outputs), a
sensor bias and an actuator bias fault, and every optional section commented out with
its default.

**Editors.** VS Code's *Even Better TOML* and other editors built on taplo check and
complete a TOML file against a JSON Schema: put `#:schema ./glrmon.schema.json` as the
file's first line, or associate the schema with your configuration files in the
editor's settings (`evenBetterToml.schema.associations`). The schema checks keys, types
and keyword lists; what depends on the model's dimensions (shapes against n, p and l,
expressions, limits) is checked by `glrmon validate`.

## Layout

```toml
[zenoh]                 # optional: the Zenoh session
[daemon]                # optional: glrmon run's workers, queues, endpoints
[recording]             # optional: MCAP recording
[recording.capture]     #   optional: inputs only around alarms

[[channels]]            # one table per channel
name = "tank"
[channels.model]        #   required: F, H, Q, R (G, J, E, Fd, S, x0, P0); or A, B, Qc
[channels.scaling]      #   optional: natural units
[channels.cdr]          #   with payload = "cdr": the ROS 2 message type
[channels.raw]          #   with payload = "raw": the f64 record layout
[channels.tags]         #   instead of key: one key per signal, samples formed
[channels.tags.keys]    #     each signal's key (and JSON field)
[channels.topics]       #   optional: a foreign recording's topics, as tags
[channels.columns]      #   optional: signal names (CSV columns) and units
[[channels.faults]]     #   the fault dictionary, one table per fault
[channels.glr]          #   optional: window, threshold, alarms, isolation
[[channels.glr.groups]] #     optional: isolation groups
[channels.glr.calibrated] #   optional: written by glrmon calibrate --write
[channels.simulation]   #   optional: how glrmon simulate drives the channel
[channels.diagnosis]    #   optional: sparse diagnosis (Zhang 2021)
[channels.consistency]  #   optional: model-consistency test
[channels.cusum]        #   with detector = "cusum": the magnitudes it is tuned for
[channels.parity]       #   optional, detector = "parity": order, evaluation
[channels.observer]     #   optional, detector = "fdf" or "uio": gains, evaluation
[channels.rls]          #   optional, detector = "rls": forgetting, evaluation
[channels.kernel]       #   with detector = "kernel": E, noise bounds, kernels
[[channels.kernel.candidates]] # optional: candidate fault functions
```

A channel's sub-tables may also be written inline, e.g.
`model = { F = [[0.9]], H = [[1.0]], Q = 0.01, R = 0.04 }` and
`faults = [{ name = "level_bias", kind = "sensor_bias", output = 0 }]`.
"#;

const FAULTS: &str = r#"
## Faults

A fault is an additive change of unknown magnitude θ from an unknown onset r (Zhang &
Basseville 2014, eq. (1); the 2014 paper's letters: **Ψ is the state fault signature,
Φ the output fault signature**):

```text
X_{k+1} = F X_k + G U_k + W_k + Ψ_k(r) θ
Y_k     = H X_k + J U_k + V_k + Φ_k(r) θ
```

Each `[[channels.faults]]` table gives the columns Ψ̃ (n entries) and Φ̃ (p entries),
either through a `kind` or explicitly:

| kind | needs | Ψ̃ (state) | Φ̃ (output) | meaning |
|---|---|---|---|---|
| `sensor_bias` | `output = j` | 0 | e_j | an offset on sensor y_j |
| `sensor_drift` | `output = j` | 0 | e_j, ramp onset | a sensor drifting linearly from r |
| `actuator_bias` | `input = i` | G e_i | J e_i | an offset on actuator u_i |
| `actuator_gain` | `input = i` | −G e_i u_i(k) | 0 | a loss of effectiveness θ of u_i (J's column must be 0) |
| `custom` (default) | `psi` and/or `phi` | `psi` | `phi` | any column; a missing one is 0 |

```toml
[[channels.faults]]
name = "level_bias"
kind = "sensor_bias"
output = 0

[[channels.faults]]
name = "leak"                      # explicit columns (n = 2, p = 2)
psi = [0.0, "-0.1*u0[-1]"]         # numbers or expressions, evaluated every sample
phi = [0.0, 0.0]
onset = "ramp"
```

**Onsets.** `onset` shapes the profile from the onset r (eqs. (4), (51)): `step` (the
default: Ψ_k(r) = Ψ̃_k·1{k ≥ r}), `impulse` (a jump that enters X_r once), `ramp`
((k − r + 1)·Ψ̃_k·1{k ≥ r}; the default and only onset of `sensor_drift`) and `known`
(the columns are the fault's whole time profile, given by expressions or data columns:
no onset search; the GLR runs over all samples). Output parts Φ act from k = r.

**Shortcuts.** `kind = "all_sensors"` stands for one `sensor_bias` per output, named
`y0_bias`, `y1_bias`, … (or after `[channels.columns]` names, `level_bias`, …), and
`kind = "all_actuators"` for one `actuator_bias` per input (`u0_bias`, …). With a
`name`, it is a prefix: `name = "s"` gives `s0`, `s1`, … A shortcut takes no `input`,
`output`, `psi` or `phi`; `onset` applies to each fault it makes.

**Units.** With `[channels.scaling]`, `sensor_*` and `actuator_*` magnitudes θ are in
the signal's raw units (the column is divided by the scale); explicit `psi`/`phi` columns
are in model units.

**Isolation groups.** By default each fault is tested against all others at an alarm;
`[[channels.glr.groups]]` tests named groups of faults together instead.
"#;

const MODEL: &str = r#"
## The model and its matrices

`[channels.model]` holds the matrices of eq. (1): F (n×n), G (n×l), H (p×n), J (p×l),
Q = cov(W) (n×n), R = cov(V) (p×p); n, l and p are read from their shapes (F gives n,
H gives p, G or J gives l).

**Matrix syntax.** A matrix is written row by row: `H = [[1.0, 0.0]]` is 1×2,
`F = [[0.9, 0.1], [0.0, 0.8]]` is 2×2. A number s stands for s·I (square matrices only:
F, Q, R, P0). Every row has the same length; no matrix is empty.

**LPV matrices.** A matrix may vary with the scheduling signals p(k) of each sample
(eq. (53)): `F = { base = [[0.9, 0.0], [0.0, 0.8]], p0 = [[0.1, 0.0], [0.0, 0.0]] }` is
F_k = M_0 + p0(k)·M_p0. The keys are `base` (required) and `p<i>`, each a matrix of the
base's shape. The samples then carry q signals (`signals`, or the highest index used + 1).

**Unknown inputs (`model.E`).** `E` (n×q, q < p) declares disturbances d_k of unknown
value entering the state, X_{k+1} = … + E d_k. The detector then runs on the innovation
decoupled from E d_k (p − q output directions), and sparse diagnosis on the Kitanidis
residual (Zhang 2021 §III-B); H E must have full column rank. A fault whose signature
lies in the range of E cannot be detected. `[channels.simulation] unknown_input` drives
d_k in simulation.

**Correlated noises (`model.S`).** S = E(W_k V_kᵀ) (n×p), as in an identified
innovation model (`glrmon identify` writes Q = K·Re·Kᵀ, R = Re, S = K·Re). Not with E.

**Noise covariances.** Q must be symmetric positive semi-definite and R (and P0)
positive definite. A constant matrix that misses by rounding only (its smallest
eigenvalue is negative by at most 10⁻⁹ of its spectral radius) is repaired with a warning.

**Continuous-time models (`A`, `B`, `Qc`).** A model from physics,
dx/dt = A x + B u + w with E[w(t)w(s)ᵀ] = Qc·δ(t − s), may be written as it is: `A`
(n×n, in 1/s), `B` (n×l) and `Qc` (n×n, the noise intensity, in state units² per
second) instead of `F`, `G`, `Q`, with the channel's `period` T in seconds, which is
then required. When the file is read the model is sampled with a zero-order hold (each
input held over the period, as a control system holds a set value): F = e^{AT} and
G = ∫₀ᵀ e^{As} ds·B from one matrix exponential of [[A, B], [0, 0]]·T, and
Q = ∫₀ᵀ e^{As}·Qc·e^{Aᵀs} ds by Van Loan's method (1978); every command then works
with that F, G, Q. The output equation is a point sample at t = kT and is not
discretised: H, J and R keep their meaning, R being the variance of each sample's
measurement noise (a continuous measurement-noise intensity means nothing for point
samples without an anti-alias filter), and so do E, S, x0, P0 and the `psi`, `phi`
fault columns (per sample). Each key excludes its discrete counterpart (F and A, G and
B, Q and Qc: an error names both). `A` cannot be an LPV table (e^{A(p)T} is not affine
in p); `B` and `Qc` can (G and Q are linear in them). With `A`, a `Q` may be given
instead of `Qc`: the covariance per sample, as `glrmon identify --model` estimates it.

```toml
[[channels]]
name = "tank"
period = 20.0              # s
[channels.model]
A = [[-1.667e-3]]          # 1/s: a time constant of 600 s
B = [[0.0556]]             # cm/s per m³/h: 1 m³/h into 0.5 m²
Qc = 1.5e-4                # cm²/s
H = [[1.0]]
R = 0.04                   # cm², per sample
```

**Natural units (`[channels.scaling]`).** The model may be written in scaled units:
each sample's raw inputs and outputs become (raw − offset) / scale on intake (and the
simulator inverts this). `u_offset`, `u_scale` have l entries, `y_offset`, `y_scale` p;
a missing list means offsets 0 or scales 1. Q, Qc, R and P0 are in model units: a
scale s turns a raw-unit variance σ² into σ²/s².

```toml
[channels.scaling]
u_offset = [50.0]          # % valve opening at the operating point
u_scale = [10.0]
y_offset = [1.2, 0.3]      # m, m³/s
y_scale = [0.1, 0.05]
```

**CSV columns (`[channels.columns]`).** `glrmon replay`, `diagnose`, `calibrate` and
`identify` read CSV files whose header names the columns. By default they are `u0`, `u1`,
…, `y0`, …, `p0`, … and every column must be one of them; with
`[channels.columns]` (`u`, `y`, `p`: lists of l, p and q names), those columns are read
and any other column of the file is skipped. The names also name the faults of the
`all_sensors`/`all_actuators` shortcuts and label the signals in reports and alarm
lines. `u_units`, `y_units`, `p_units` give each signal's raw unit (as the plant
gives it, before `[channels.scaling]`): reports and `validate` show
`LI201 [cm]`, and a bias fault's magnitude is then in that unit.

```toml
[channels.columns]
u = ["FIC101", "FIC102"]
y = ["LI201", "LI202", "FI301"]
u_units = ["m³/h", "m³/h"]
y_units = ["cm", "cm", "m³/h"]
```
"#;

const EXPRESSIONS: &str = r#"
## Expressions

Fault columns (`psi`, `phi`) may hold expressions, strings evaluated at every sample;
`[channels.simulation]` lists are expressions of the sample index. Nothing is executed:
the evaluator knows only the operations below, and no expression can exhaust the
stack or the memory.

| element | syntax |
|---|---|
| numbers | `2`, `2.`, `.5`, `1e-3`, `1.5E+3` |
| known inputs | `u0`, `u1`, … (u_i(k)) |
| scheduling signals | `p0`, `p1`, … (p_i(k)) |
| past values | `u0[-1]` is u_0(k − 1), `p2[-3]` is p_2(k − 3); `u0[0]` is `u0`; no future (`[1]`) |
| sample index | `k` (as a number) |
| operators | `+ - * /`, unary `-` and `+`, `^` (power, right-associative: `2^3^2` = 2⁹; `-2^2` = −4) |
| functions of one argument | `sin cos tan exp log sqrt abs` (`log` is the natural logarithm) |
| functions of two | `min max pow` |
| random | `uniform(a, b)` (on [a, b)), `normal(mean, sd)` |
| constants | `pi`, `e` |
| grouping | `( … )`; spaces, tabs and newlines anywhere between tokens |

Where each is allowed:

| where | `u<i>`, `p<i>` | lags `[-n]` | `k` | random |
|---|---|---|---|---|
| fault columns `psi`, `phi` | yes | yes | yes | no |
| `simulation.inputs`, `signals`, `unknown_input` | no | no | yes | yes |

The outputs Y are not variables: a fault signature depends on what is known before the
sample is measured. A constant sub-expression is folded when the file is read, and one
that is not finite (`1/0`, `log(0)`, `1e999`) is an error; `u0/p0` with p0 = 0 is an
IEEE ±inf or NaN at run time, which `glrmon validate` reports on the simulated samples.

```toml
psi = ["0.5*u0[-1] - p3", 0.0]               # a column that follows the input
phi = ["max(0, p0 - 1.5)", "exp(-0.01*k)"]
[channels.simulation]
inputs = ["sin(0.05*k) + normal(0, 0.1)"]
```
"#;
