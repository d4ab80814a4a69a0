//! Small arithmetic expressions of the configuration, parsed once and evaluated per
//! sample.
//!
//! Users write fault-column entries such as `"0.5*u0[-1] - p3"` and simulated signals
//! such as `"exp(-k)"` or `"uniform(-17.3, 17.3)"`. [`Expr::parse`] turns the text into
//! a node arena; [`Expr::eval`] walks it with no heap allocation and no panic. Nothing
//! is ever executed: the evaluator knows only the operations below.
//!
//! # Grammar
//!
//! ```text
//! expr    := term (("+" | "-") term)*            left-associative: 2-3-4 = (2-3)-4
//! term    := unary (("*" | "/") unary)*          left-associative
//! unary   := ("-" | "+") unary | power
//! power   := primary ("^" unary)?                right-associative: 2^3^2 = 2^9
//! primary := number | "(" expr ")" | constant | variable
//!          | function "(" expr ("," expr)* ")"
//! variable := "k" | "t" | "x" digits | ("u" | "p") digits ("[" ("-" | "+")? digits "]")?
//! ```
//!
//! - Numbers: `2`, `2.`, `.5`, `1e-3`, `1.5E+3`.
//! - Variables: `u<i>` known input i, `p<i>` exogenous (scheduling) signal i, `k` the
//!   sample index as f64. `u0[-3]` / `p2[-1]` read the value at sample k − 3 / k − 1;
//!   `u0[0]` is `u0`; positive lags (the future) are errors. Only where the context
//!   allows them (a candidate fault function of the `kernel` detector): `x<i>` the
//!   estimated state i (0-based, no lags) and `t` the time in seconds.
//! - Operators: `+ - * /`, unary `-` and `+`, `^` (power). Unary minus binds looser
//!   than `^`, as in mathematics and Python: `-2^2 = -(2^2) = -4`, while `2^-1 = 0.5`.
//! - Functions: `sin cos tan exp log sqrt abs` (one argument; `log` is the natural
//!   logarithm), `min max pow` (two arguments); `uniform(a, b)` (uniform on \[a, b)) and
//!   `normal(mean, sd)` only where the context allows randomness.
//! - Constants: `pi`, `e`.
//! - Whitespace (space, tab, newline) anywhere between tokens.
//!
//! Arithmetic is IEEE: `u0/p0` with p0 = 0 evaluates to ±inf or NaN (the detector
//! rejects non-finite matrices itself). A sub-expression that uses no variable and
//! no random function is folded at parse time, and one that is not finite (`1e999`,
//! `1/0`, `log(0)`) is rejected with [`ExprError::NonFiniteConstant`].
//!
//! Sources longer than [`MAX_LEN`] bytes, nested deeper than [`MAX_DEPTH`] levels or
//! with lags beyond [`MAX_LAG`] are rejected, so no input string can exhaust the stack
//! or the memory.
//!
//! # Examples
//! ```
//! use glrmon_spec::expr::{Env, Expr, ExprContext, SignalHistory};
//! let ctx = ExprContext::fault_column(1, 1);
//! let e = Expr::parse("0.5*u0[-1] - p0", &ctx).unwrap();
//! let mut history = SignalHistory::new(e.max_lag(), 1, 1);
//! history.push(&[4.0], &[0.0]); // sample 0
//! let mut env = Env { k: 1, u: &[1.0], p: &[0.5], history: &history, random: None };
//! assert_eq!(e.eval(&mut env), 1.5);
//! ```

mod parse;

use std::fmt;

use glrmon_core::{CandidateFn, ColumnFn, Signals, SystemMatrices};

/// The longest source accepted by [`Expr::parse`], in bytes.
pub const MAX_LEN: usize = 4096;

/// The deepest nesting accepted by [`Expr::parse`]: levels of parentheses, function
/// calls, unary signs and power exponents.
pub const MAX_DEPTH: usize = 64;

/// The largest lag accepted by [`Expr::parse`] (`u0[-10000]`), which bounds the
/// memory of a [`SignalHistory`].
pub const MAX_LAG: usize = 10_000;

/// What an expression may refer to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExprContext {
    /// Number of known inputs: `u0` … `u{inputs−1}` exist.
    pub inputs: usize,
    /// Number of exogenous signals: `p0` … `p{signals−1}` exist.
    pub signals: usize,
    /// Whether the sample index `k` may be used.
    pub allow_k: bool,
    /// Whether lagged variables such as `u0[-1]` may be used.
    pub allow_lags: bool,
    /// Whether the random functions `uniform` and `normal` may be used.
    pub allow_random: bool,
    /// Number of states the expression may read: `x0` … `x{states−1}` exist (0 in
    /// every context but a candidate fault function's).
    pub states: usize,
    /// Whether the time `t` (seconds) may be used.
    pub allow_t: bool,
}

impl ExprContext {
    /// The context of a fault-column entry: inputs, signals and their lags, but neither
    /// `k` (a fault signature must not depend on the absolute sample index) nor random
    /// functions (the column must be deterministic).
    #[must_use]
    pub fn fault_column(inputs: usize, signals: usize) -> Self {
        Self {
            inputs,
            signals,
            allow_k: false,
            allow_lags: true,
            allow_random: false,
            states: 0,
            allow_t: false,
        }
    }

    /// The context of a candidate fault function φ(t, x, u) of the `kernel` detector:
    /// the inputs, the estimated state `x0` … `x{states−1}` and the time `t`, without
    /// lags (the function is evaluated only during an isolation episode, so no
    /// history is kept), `k`, scheduling signals (φ receives none) or randomness.
    #[must_use]
    pub fn candidate(inputs: usize, states: usize) -> Self {
        Self {
            inputs,
            signals: 0,
            allow_k: false,
            allow_lags: false,
            allow_random: false,
            states,
            allow_t: true,
        }
    }
}

/// Why a source is not a valid expression. Every variant names the offending text and
/// its byte position in the source, where there is one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ExprError {
    /// A name that is neither a variable of the context, nor a constant, nor a function
    /// (e.g. `u7` with two inputs).
    #[error("unknown signal \"{name}\" ({hint})")]
    UnknownSignal {
        /// The name as written.
        name: String,
        /// Its byte position.
        pos: usize,
        /// What exists instead, e.g. `the channel has 2 inputs: u0..u1`.
        hint: String,
    },
    /// A call of a function that does not exist.
    #[error("unknown function \"{name}\" at byte {pos} (known functions: {known})")]
    UnknownFunction {
        /// The name as written.
        name: String,
        /// Its byte position.
        pos: usize,
        /// The functions available in this context.
        known: &'static str,
    },
    /// A function called with the wrong number of arguments.
    #[error(
        "function \"{name}\" at byte {pos} takes {expected} {}, found {found}",
        arguments(.expected)
    )]
    WrongArity {
        /// The function's name.
        name: String,
        /// Its byte position.
        pos: usize,
        /// The number of arguments it takes.
        expected: usize,
        /// The number of arguments given.
        found: usize,
    },
    /// The text does not follow the grammar.
    #[error("syntax error at byte {pos}: expected {expected}, found {found}")]
    Syntax {
        /// Byte position of the offending token (the source length at its end).
        pos: usize,
        /// What the grammar allows there.
        expected: &'static str,
        /// The offending token, quoted, or `end of expression`.
        found: String,
    },
    /// A feature the context forbids: `k`, `t`, lags or random functions.
    #[error("{what} not allowed here: \"{text}\" at byte {pos}")]
    NotAllowed {
        /// `"k"`, `"t"`, `"lags"` or `"random functions"`.
        what: &'static str,
        /// The offending text, e.g. `u0[-1]`.
        text: String,
        /// Its byte position.
        pos: usize,
    },
    /// A lag that reads the future, e.g. `u0[2]`.
    #[error(
        "positive lag in \"{text}\" at byte {pos}: only past samples can be read \
         (u0[-1] is the previous sample)"
    )]
    PositiveLag {
        /// The lagged variable as written.
        text: String,
        /// Its byte position.
        pos: usize,
    },
    /// A lag beyond [`MAX_LAG`].
    #[error("lag too large in \"{text}\" at byte {pos}: at most {max} samples back")]
    LagTooLarge {
        /// The lagged variable as written.
        text: String,
        /// Its byte position.
        pos: usize,
        /// The largest lag accepted.
        max: usize,
    },
    /// A source longer than [`MAX_LEN`] bytes.
    #[error("expression too long: {len} bytes, the limit is {max}")]
    TooLong {
        /// The source's length in bytes.
        len: usize,
        /// The limit.
        max: usize,
    },
    /// A source nested deeper than [`MAX_DEPTH`] levels.
    #[error("expression nested too deeply at byte {pos} (\"{text}\"): the limit is {max} levels")]
    TooDeep {
        /// The token that opens the level beyond the limit.
        text: String,
        /// Its byte position.
        pos: usize,
        /// The limit.
        max: usize,
    },
    /// A number or constant sub-expression that is not finite (`1e999`, `1/0`).
    #[error("\"{text}\" at byte {pos} is not a finite number")]
    NonFiniteConstant {
        /// The number or sub-expression as written.
        text: String,
        /// Its byte position.
        pos: usize,
    },
}

fn arguments(n: &usize) -> &'static str {
    if *n == 1 { "argument" } else { "arguments" }
}

/// A source of random numbers for `uniform` and `normal` (implemented by the
/// simulator's seeded generator).
pub trait RandomSource {
    /// A uniform draw in \[0, 1).
    fn uniform(&mut self) -> f64;
    /// A standard normal draw, N(0, 1).
    fn normal(&mut self) -> f64;
}

/// The values an expression sees at sample k.
///
/// A variable whose index lies beyond `u` or `p` reads as NaN (a caller bug made
/// visible rather than hidden); so do the random functions when `random` is `None`.
pub struct Env<'a> {
    /// The sample index, read by `k`.
    pub k: u64,
    /// U_k, read by `u<i>` and `u<i>[0]`.
    pub u: &'a [f64],
    /// p(k), read by `p<i>` and `p<i>[0]`.
    pub p: &'a [f64],
    /// Past samples, read by `u<i>[-lag]` and `p<i>[-lag]`.
    pub history: &'a SignalHistory,
    /// The source of `uniform` and `normal`, if the context allows them.
    pub random: Option<&'a mut dyn RandomSource>,
}

impl fmt::Debug for Env<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Env")
            .field("k", &self.k)
            .field("u", &self.u)
            .field("p", &self.p)
            .field("history", &self.history)
            .field("random", &self.random.is_some())
            .finish()
    }
}

/// The estimated state and the time a candidate fault function's expression reads
/// (`x<i>`, `t`), beside its [`Env`]; [`Expr::eval`] gives it none (`x<i>` reads NaN,
/// `t` 0).
#[derive(Debug, Clone, Copy, Default)]
pub struct StateEnv<'a> {
    /// x̂, read by `x<i>`.
    pub x: &'a [f64],
    /// The time in seconds, read by `t`.
    pub t: f64,
}

/// Past samples' inputs and signals, for lagged variables: a ring buffer of fixed
/// capacity (the largest lag), allocated once.
///
/// Call [`SignalHistory::push`] with the current sample *after* evaluating the
/// expressions at it, so that lag 1 is the previous sample.
#[derive(Debug, Clone)]
pub struct SignalHistory {
    inputs: usize,
    signals: usize,
    capacity: usize,
    /// `capacity` rows of `inputs + signals` values, one row per sample.
    data: Vec<f64>,
    /// The row the next push writes.
    next: usize,
    /// Rows written so far, at most `capacity`.
    filled: usize,
}

impl SignalHistory {
    /// A history of the last `lags` samples of `inputs` inputs and `signals` signals,
    /// all reading 0.0 until pushed.
    ///
    /// # Panics
    /// If `lags·(inputs + signals)` values cannot be allocated; expressions bound their
    /// lags by [`MAX_LAG`].
    #[must_use]
    pub fn new(lags: usize, inputs: usize, signals: usize) -> Self {
        let width = inputs.saturating_add(signals);
        Self {
            inputs,
            signals,
            capacity: lags,
            data: vec![0.0; lags.saturating_mul(width)],
            next: 0,
            filled: 0,
        }
    }

    /// Records the current sample (after the expressions were evaluated at it). Missing
    /// entries (slices shorter than the history's width) are stored as NaN, extra ones
    /// are ignored. Does nothing when the capacity is 0.
    pub fn push(&mut self, u: &[f64], p: &[f64]) {
        if self.capacity == 0 {
            return;
        }
        let width = self.inputs.saturating_add(self.signals);
        let start = self.next.saturating_mul(width);
        if let Some(row) = self.data.get_mut(start..start.saturating_add(width)) {
            let (row_u, row_p) = row.split_at_mut(self.inputs.min(row.len()));
            for (i, x) in row_u.iter_mut().enumerate() {
                *x = u.get(i).copied().unwrap_or(f64::NAN);
            }
            for (i, x) in row_p.iter_mut().enumerate() {
                *x = p.get(i).copied().unwrap_or(f64::NAN);
            }
        }
        self.next = (self.next + 1) % self.capacity;
        self.filled = (self.filled + 1).min(self.capacity);
    }

    /// Input `index` at `lag` samples back (lag ≥ 1). Samples before the first push
    /// read as 0.0; lag 0 (the current sample is in [`Env`], not here), a lag beyond the
    /// capacity and an index beyond the inputs read as NaN.
    #[must_use]
    pub fn input(&self, index: usize, lag: usize) -> f64 {
        if index >= self.inputs {
            return f64::NAN;
        }
        self.value(index, lag)
    }

    /// Signal `index` at `lag` samples back, as [`SignalHistory::input`].
    #[must_use]
    pub fn signal(&self, index: usize, lag: usize) -> f64 {
        if index >= self.signals {
            return f64::NAN;
        }
        self.value(self.inputs.saturating_add(index), lag)
    }

    /// The capacity: the largest lag stored.
    #[must_use]
    pub fn lags(&self) -> usize {
        self.capacity
    }

    /// Forgets every pushed sample: all lags read 0.0 again.
    pub fn reset(&mut self) {
        self.next = 0;
        self.filled = 0;
    }

    fn value(&self, column: usize, lag: usize) -> f64 {
        if lag == 0 || lag > self.capacity {
            return f64::NAN;
        }
        if lag > self.filled {
            return 0.0;
        }
        // 1 ≤ lag ≤ capacity and next < capacity: no overflow either way.
        let row = if lag <= self.next {
            self.next - lag
        } else {
            self.next + (self.capacity - lag)
        };
        let width = self.inputs.saturating_add(self.signals);
        self.data
            .get(row.saturating_mul(width).saturating_add(column))
            .copied()
            .unwrap_or(f64::NAN)
    }
}

/// One-argument operations.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Op1 {
    Neg,
    Sin,
    Cos,
    Tan,
    Exp,
    Log,
    Sqrt,
    Abs,
}

impl Op1 {
    fn apply(self, x: f64) -> f64 {
        match self {
            Op1::Neg => -x,
            Op1::Sin => x.sin(),
            Op1::Cos => x.cos(),
            Op1::Tan => x.tan(),
            Op1::Exp => x.exp(),
            Op1::Log => x.ln(),
            Op1::Sqrt => x.sqrt(),
            Op1::Abs => x.abs(),
        }
    }
}

/// Two-argument operations.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Op2 {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
    Min,
    Max,
}

impl Op2 {
    fn apply(self, x: f64, y: f64) -> f64 {
        match self {
            Op2::Add => x + y,
            Op2::Sub => x - y,
            Op2::Mul => x * y,
            Op2::Div => x / y,
            Op2::Pow => x.powf(y),
            Op2::Min => x.min(y),
            Op2::Max => x.max(y),
        }
    }
}

/// A node of the arena; children are indices of earlier nodes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Node {
    Const(f64),
    K,
    T,
    State(usize),
    Input(usize),
    Signal(usize),
    LagInput {
        index: usize,
        lag: usize,
    },
    LagSignal {
        index: usize,
        lag: usize,
    },
    Unary(Op1, usize),
    Binary(Op2, usize, usize),
    /// `first op₁ x₁ op₂ x₂ …`, left to right; the links are `links[start..start + len]`.
    Chain {
        first: usize,
        start: usize,
        len: usize,
    },
    Uniform(usize, usize),
    Normal(usize, usize),
}

/// The functions, by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Func {
    One(Op1),
    Two(Op2),
    Uniform,
    Normal,
}

impl Func {
    fn lookup(name: &str) -> Option<Func> {
        Some(match name {
            "sin" => Func::One(Op1::Sin),
            "cos" => Func::One(Op1::Cos),
            "tan" => Func::One(Op1::Tan),
            "exp" => Func::One(Op1::Exp),
            "log" => Func::One(Op1::Log),
            "sqrt" => Func::One(Op1::Sqrt),
            "abs" => Func::One(Op1::Abs),
            "min" => Func::Two(Op2::Min),
            "max" => Func::Two(Op2::Max),
            "pow" => Func::Two(Op2::Pow),
            "uniform" => Func::Uniform,
            "normal" => Func::Normal,
            _ => return None,
        })
    }

    fn arity(self) -> usize {
        match self {
            Func::One(_) => 1,
            Func::Two(_) | Func::Uniform | Func::Normal => 2,
        }
    }

    fn is_random(self) -> bool {
        matches!(self, Func::Uniform | Func::Normal)
    }
}

const FUNCTIONS: &str = "sin, cos, tan, exp, log, sqrt, abs, min, max, pow";
const FUNCTIONS_RANDOM: &str = "sin, cos, tan, exp, log, sqrt, abs, min, max, pow, uniform, normal";

/// A compiled expression: a node arena (children before parents, the root last),
/// evaluated recursively with no heap allocation.
///
/// A left-associative chain such as `a + b - c + …` is one node whose operands are
/// evaluated in a loop, so the recursion depth is bounded by the nesting limit
/// [`MAX_DEPTH`], not by the length of the source.
///
/// Sub-expressions without variables or random functions are folded into constants at
/// parse time.
#[derive(Debug, Clone)]
pub struct Expr {
    source: String,
    nodes: Vec<Node>,
    /// The (operator, operand) links of the [`Node::Chain`] nodes.
    links: Vec<(Op2, usize)>,
    root: usize,
    max_lag: usize,
    uses_random: bool,
    uses_k: bool,
    highest_input: Option<usize>,
    highest_signal: Option<usize>,
    highest_state: Option<usize>,
}

impl Expr {
    /// Parses `src` against what `ctx` allows.
    ///
    /// # Errors
    /// An [`ExprError`] naming the offending text and its byte position: unknown names
    /// and functions, wrong arity, syntax errors, features the context forbids,
    /// positive or too large lags, a source too long or too deeply nested, a constant
    /// that is not finite. Never panics, whatever the string.
    pub fn parse(src: &str, ctx: &ExprContext) -> Result<Expr, ExprError> {
        if src.len() > MAX_LEN {
            return Err(ExprError::TooLong {
                len: src.len(),
                max: MAX_LEN,
            });
        }
        parse::parse(src, ctx)
    }

    /// The source text, as given to [`Expr::parse`].
    #[must_use]
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The largest lag used (`u0[-3]` → 3), 0 if none: the capacity the
    /// [`SignalHistory`] needs.
    #[must_use]
    pub fn max_lag(&self) -> usize {
        self.max_lag
    }

    /// The value, when the expression uses no variable and no random function.
    #[must_use]
    pub fn constant_value(&self) -> Option<f64> {
        match self.nodes.get(self.root) {
            Some(Node::Const(v)) => Some(*v),
            _ => None,
        }
    }

    /// Whether `uniform` or `normal` is used.
    #[must_use]
    pub fn uses_random(&self) -> bool {
        self.uses_random
    }

    /// Whether the sample index `k` is used.
    #[must_use]
    pub fn uses_k(&self) -> bool {
        self.uses_k
    }

    /// The highest input index used (`u3` → 3), lagged or not.
    #[must_use]
    pub fn highest_input(&self) -> Option<usize> {
        self.highest_input
    }

    /// The highest signal index used (`p3` → 3), lagged or not.
    #[must_use]
    pub fn highest_signal(&self) -> Option<usize> {
        self.highest_signal
    }

    /// The highest state index used (`x3` → 3).
    #[must_use]
    pub fn highest_state(&self) -> Option<usize> {
        self.highest_state
    }

    /// The value at the sample described by `env`. Takes `&self`, allocates nothing,
    /// never panics; arithmetic is IEEE (division by zero gives ±inf or NaN).
    pub fn eval(&self, env: &mut Env<'_>) -> f64 {
        self.eval_node(self.root, env, StateEnv::default())
    }

    /// [`Expr::eval`] with the estimated state and the time of `state` (for the
    /// `x<i>` and `t` of a candidate fault function); a state index beyond
    /// `state.x` reads NaN.
    pub fn eval_with_state(&self, env: &mut Env<'_>, state: StateEnv<'_>) -> f64 {
        self.eval_node(self.root, env, state)
    }

    fn eval_node(&self, i: usize, env: &mut Env<'_>, st: StateEnv<'_>) -> f64 {
        let Some(node) = self.nodes.get(i) else {
            return f64::NAN;
        };
        match *node {
            Node::Const(v) => v,
            Node::K => env.k as f64,
            Node::T => st.t,
            Node::State(j) => st.x.get(j).copied().unwrap_or(f64::NAN),
            Node::Input(j) => env.u.get(j).copied().unwrap_or(f64::NAN),
            Node::Signal(j) => env.p.get(j).copied().unwrap_or(f64::NAN),
            Node::LagInput { index, lag } => env.history.input(index, lag),
            Node::LagSignal { index, lag } => env.history.signal(index, lag),
            Node::Unary(op, a) => op.apply(self.eval_node(a, env, st)),
            Node::Binary(op, a, b) => {
                let x = self.eval_node(a, env, st);
                let y = self.eval_node(b, env, st);
                op.apply(x, y)
            }
            Node::Chain { first, start, len } => {
                let mut acc = self.eval_node(first, env, st);
                match self.links.get(start..start.saturating_add(len)) {
                    Some(links) => {
                        for &(op, x) in links {
                            acc = op.apply(acc, self.eval_node(x, env, st));
                        }
                        acc
                    }
                    None => f64::NAN,
                }
            }
            Node::Uniform(a, b) => {
                let lo = self.eval_node(a, env, st);
                let hi = self.eval_node(b, env, st);
                match env.random.as_deref_mut() {
                    Some(r) => lo + (hi - lo) * r.uniform(),
                    None => f64::NAN,
                }
            }
            Node::Normal(a, b) => {
                let mean = self.eval_node(a, env, st);
                let sd = self.eval_node(b, env, st);
                match env.random.as_deref_mut() {
                    Some(r) => mean + sd * r.normal(),
                    None => f64::NAN,
                }
            }
        }
    }
}

impl fmt::Display for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.source)
    }
}

/// A fault column whose entries are expressions, e.g. Ψ̃ = `["0.5*u0[-1] - p3", "0"]`.
///
/// [`ColumnFn::evaluate`] must be called once per sample, in order (as the detector
/// does, including its predict-only steps): each call records the sample for the
/// lagged variables of the next ones.
#[derive(Debug)]
pub struct ExprColumn {
    exprs: Vec<Expr>,
    history: SignalHistory,
}

impl ExprColumn {
    /// A column of `exprs` (one per entry) over `inputs` inputs and `signals` signals;
    /// the history holds the largest lag of the entries.
    #[must_use]
    pub fn new(exprs: Vec<Expr>, inputs: usize, signals: usize) -> Self {
        let lags = exprs.iter().map(Expr::max_lag).max().unwrap_or(0);
        Self {
            history: SignalHistory::new(lags, inputs, signals),
            exprs,
        }
    }

    /// The number of entries.
    #[must_use]
    pub fn len(&self) -> usize {
        self.exprs.len()
    }

    /// Whether the column has no entry.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.exprs.is_empty()
    }

    /// The entries.
    #[must_use]
    pub fn exprs(&self) -> &[Expr] {
        &self.exprs
    }
}

impl ColumnFn for ExprColumn {
    /// Evaluates each entry at sample k (no random source: random functions read NaN;
    /// entries of `out` beyond the column's length are set to NaN), then records the
    /// sample's signals for the lags.
    fn evaluate(
        &mut self,
        k: u64,
        signals: &Signals<'_>,
        _system: &SystemMatrices,
        out: &mut [f64],
    ) {
        let mut env = Env {
            k,
            u: signals.u,
            p: signals.p,
            history: &self.history,
            random: None,
        };
        for (i, o) in out.iter_mut().enumerate() {
            *o = match self.exprs.get(i) {
                Some(e) => e.eval(&mut env),
                None => f64::NAN,
            };
        }
        self.history.push(signals.u, signals.p);
    }
}

/// A candidate fault function φ(t, x, u) of the `kernel` detector whose p⋆ entries are
/// expressions of the context [`ExprContext::candidate`], e.g.
/// `["x1 + x2", "cos(x3)", "cos(0.5*x4)"]`.
#[derive(Debug)]
pub struct ExprCandidate {
    exprs: Vec<Expr>,
    /// Empty (candidates have no lags): [`Env`] needs one.
    history: SignalHistory,
}

impl ExprCandidate {
    /// A candidate of `exprs` (one per fault channel) over `inputs` inputs.
    #[must_use]
    pub fn new(exprs: Vec<Expr>, inputs: usize) -> Self {
        Self {
            exprs,
            history: SignalHistory::new(0, inputs, 0),
        }
    }

    /// The entries.
    #[must_use]
    pub fn exprs(&self) -> &[Expr] {
        &self.exprs
    }
}

impl CandidateFn for ExprCandidate {
    /// Evaluates each entry at (t, x, u), allocating nothing; entries of `out` beyond
    /// the candidate's length are set to NaN (which the detector refuses).
    fn evaluate(&mut self, t: f64, x: &[f64], u: &[f64], out: &mut [f64]) {
        let mut env = Env {
            k: 0,
            u,
            p: &[],
            history: &self.history,
            random: None,
        };
        let state = StateEnv { x, t };
        for (i, o) in out.iter_mut().enumerate() {
            *o = match self.exprs.get(i) {
                Some(e) => e.eval_with_state(&mut env, state),
                None => f64::NAN,
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glrmon_core::{ColumnFn, Dims, Signals, SystemMatrices};
    use proptest::prelude::*;

    /// Everything allowed: 2 inputs, 3 signals.
    fn all() -> ExprContext {
        ExprContext {
            inputs: 2,
            signals: 3,
            allow_k: true,
            allow_lags: true,
            allow_random: true,
            states: 0,
            allow_t: false,
        }
    }

    /// A source returning fixed draws, counting them.
    #[derive(Debug, Default)]
    struct Fixed {
        uniform: f64,
        normal: f64,
        draws: usize,
    }

    impl RandomSource for Fixed {
        fn uniform(&mut self) -> f64 {
            self.draws += 1;
            self.uniform
        }
        fn normal(&mut self) -> f64 {
            self.draws += 1;
            self.normal
        }
    }

    fn parse(src: &str) -> Expr {
        Expr::parse(src, &all()).unwrap_or_else(|e| panic!("{src}: {e}"))
    }

    fn err(src: &str, ctx: &ExprContext) -> ExprError {
        match Expr::parse(src, ctx) {
            Ok(e) => panic!("{src} parsed as {e:?}"),
            Err(e) => e,
        }
    }

    /// Value at k = 7, u = [1, 2], p = [10, 20, 30], empty history, no random source.
    fn value(src: &str) -> f64 {
        let e = parse(src);
        let history = SignalHistory::new(0, 2, 3);
        let mut env = Env {
            k: 7,
            u: &[1.0, 2.0],
            p: &[10.0, 20.0, 30.0],
            history: &history,
            random: None,
        };
        e.eval(&mut env)
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * b.abs().max(1.0)
    }

    #[test]
    fn numbers_in_every_spelling() {
        for (src, v) in [
            ("2", 2.0),
            ("2.", 2.0),
            (".5", 0.5),
            ("1e-3", 1e-3),
            ("1.5E+3", 1500.0),
            ("  42\t\n", 42.0),
            ("0.25e2", 25.0),
        ] {
            assert_eq!(parse(src).constant_value(), Some(v), "{src}");
        }
    }

    #[test]
    fn precedence_and_associativity() {
        for (src, v) in [
            ("2-3-4", -5.0),  // left-associative
            ("2/4/2", 0.25),  // left-associative
            ("1+2*3", 7.0),   // * before +
            ("(1+2)*3", 9.0), // parentheses
            ("2^3^2", 512.0), // right-associative: 2^(3^2)
            ("-2^2", -4.0),   // documented choice: -(2^2)
            ("(-2)^2", 4.0),  //
            ("2^-1", 0.5),    // signed exponent
            ("-2*3", -6.0),   //
            ("2*-3", -6.0),   //
            ("--2", 2.0),     // repeated signs
            ("+2", 2.0),      // unary plus
            ("2*3^2", 18.0),  // ^ before *
            ("-3-(-3)", 0.0), //
            ("10-2*3+4/2", 6.0),
        ] {
            assert_eq!(parse(src).constant_value(), Some(v), "{src}");
        }
    }

    #[test]
    fn functions_and_constants() {
        use std::f64::consts::{E, PI};
        for (src, v) in [
            ("sin(pi/2)", 1.0),
            ("cos(0)", 1.0),
            ("tan(pi/4)", 1.0),
            ("exp(1)", E),
            ("log(e)", 1.0),
            ("sqrt(16)", 4.0),
            ("abs(-3)", 3.0),
            ("min(2, 3)", 2.0),
            ("max(2, 3)", 3.0),
            ("pow(2, 10)", 1024.0),
            ("2*pi", 2.0 * PI),
            ("max(min(1, 2), sqrt(abs(-9)))", 3.0),
            ("exp(-0)", 1.0),
        ] {
            let got = parse(src).constant_value().unwrap();
            assert!(close(got, v), "{src}: {got} != {v}");
        }
    }

    #[test]
    fn variables_read_the_environment() {
        assert_eq!(value("u1"), 2.0);
        assert_eq!(value("p2"), 30.0);
        assert_eq!(value("k"), 7.0);
        assert_eq!(value("0.5*u0 - p1"), -19.5);
        assert_eq!(value("exp(-k)"), (-7.0f64).exp());
        assert_eq!(value("u0[0] + p0[-0]"), 11.0);
        assert_eq!(value(" u1 ^ 2 * sin( 0 ) + max ( u0 , p0 ) "), 10.0);
        let e = parse("u1 + p2[-4] + k");
        assert_eq!(e.constant_value(), None);
        assert_eq!(e.highest_input(), Some(1));
        assert_eq!(e.highest_signal(), Some(2));
        assert!(e.uses_k());
        assert!(!e.uses_random());
    }

    #[test]
    fn out_of_range_environment_reads_nan() {
        let e = parse("u1 + p2");
        let history = SignalHistory::new(0, 0, 0);
        let mut env = Env {
            k: 0,
            u: &[1.0],
            p: &[],
            history: &history,
            random: None,
        };
        assert!(e.eval(&mut env).is_nan());
    }

    #[test]
    fn division_by_zero_follows_ieee() {
        let e = parse("u0/p0");
        let history = SignalHistory::new(0, 2, 3);
        let mut env = Env {
            k: 0,
            u: &[1.0, 0.0],
            p: &[0.0, 0.0, 0.0],
            history: &history,
            random: None,
        };
        assert_eq!(e.eval(&mut env), f64::INFINITY);
        env.u = &[-1.0, 0.0];
        assert_eq!(e.eval(&mut env), f64::NEG_INFINITY);
        env.u = &[0.0, 0.0];
        assert!(e.eval(&mut env).is_nan());
        assert!(value("log(u0 - 2)").is_nan());
    }

    #[test]
    fn constants_fold_into_one_node() {
        let e = parse("1 + 2*3 - sin(0) + pi^2");
        assert_eq!(e.nodes.len(), 1);
        assert!(close(
            e.constant_value().unwrap(),
            7.0 + std::f64::consts::PI.powi(2)
        ));
        // Folding stops at variables but folds the constant parts around them.
        let e = parse("u0 * (2 + 3) - 4*5");
        assert_eq!(e.nodes.len(), 5, "{:?}", e.nodes);
        assert_eq!(value("u0 * (2 + 3) - 4*5"), -15.0);
        // Random draws never fold.
        let e = parse("uniform(0, 1)");
        assert_eq!(e.constant_value(), None);
        assert!(e.uses_random());
        assert_eq!(parse("normal(1, 2) * 0").constant_value(), None);
    }

    #[test]
    fn lags_read_the_history_over_several_pushes() {
        let ctx = ExprContext::fault_column(1, 2);
        let lag1 = Expr::parse("u0[-1]", &ctx).unwrap();
        let lag2 = Expr::parse("p1[-2]", &ctx).unwrap();
        let diff = Expr::parse("u0 - u0[-3]", &ctx).unwrap();
        let mixed = Expr::parse("0.5*u0[-1] - p1", &ctx).unwrap();
        assert_eq!(lag1.max_lag(), 1);
        assert_eq!(lag2.max_lag(), 2);
        assert_eq!(diff.max_lag(), 3);
        assert_eq!(Expr::parse("u0[0] + p0", &ctx).unwrap().max_lag(), 0);
        let mut history = SignalHistory::new(3, 1, 2);
        let mut seen = Vec::new();
        for k in 0..6u64 {
            let u = [k as f64 * 10.0];
            let p = [0.0, k as f64 + 100.0];
            let mut env = Env {
                k,
                u: &u,
                p: &p,
                history: &history,
                random: None,
            };
            seen.push([
                lag1.eval(&mut env),
                lag2.eval(&mut env),
                diff.eval(&mut env),
                mixed.eval(&mut env),
            ]);
            history.push(&u, &p);
        }
        // Values before the first sample read as 0.0.
        assert_eq!(
            seen,
            vec![
                [0.0, 0.0, 0.0, -100.0],
                [0.0, 0.0, 10.0, -101.0],
                [10.0, 100.0, 20.0, -97.0],
                [20.0, 101.0, 30.0, -93.0],
                [30.0, 102.0, 30.0, -89.0],
                [40.0, 103.0, 30.0, -85.0],
            ]
        );
    }

    #[test]
    fn signal_history_ring_wraps_and_guards_its_edges() {
        let mut h = SignalHistory::new(2, 1, 1);
        assert_eq!(h.lags(), 2);
        assert_eq!(h.input(0, 1), 0.0);
        for i in 0..5 {
            h.push(&[f64::from(i)], &[f64::from(-i)]);
        }
        assert_eq!(h.input(0, 1), 4.0);
        assert_eq!(h.input(0, 2), 3.0);
        assert_eq!(h.signal(0, 1), -4.0);
        assert_eq!(h.signal(0, 2), -3.0);
        assert!(h.input(0, 0).is_nan(), "lag 0 is not stored");
        assert!(h.input(0, 3).is_nan(), "beyond the capacity");
        assert!(h.input(1, 1).is_nan(), "no such input");
        assert!(h.signal(1, 1).is_nan(), "no such signal");
        // Short slices store NaN, long ones are cut.
        h.push(&[], &[7.0, 8.0]);
        assert!(h.input(0, 1).is_nan());
        assert_eq!(h.signal(0, 1), 7.0);
        h.reset();
        assert_eq!(h.input(0, 1), 0.0);
        // Capacity 0 ignores pushes.
        let mut empty = SignalHistory::new(0, 2, 2);
        empty.push(&[1.0, 2.0], &[3.0, 4.0]);
        assert!(empty.input(0, 1).is_nan());
        // No signals but a huge capacity: no overflow anywhere.
        let mut wide = SignalHistory::new(usize::MAX, 0, 0);
        wide.push(&[1.0], &[]);
        assert!(wide.input(0, usize::MAX).is_nan());
        assert!(wide.signal(0, 1).is_nan());
    }

    #[test]
    fn random_functions_draw_from_the_source() {
        let mut rng = Fixed {
            uniform: 0.5,
            normal: 1.5,
            draws: 0,
        };
        let history = SignalHistory::new(0, 0, 0);
        let uniform = parse("uniform(-17.3, 17.3)");
        let normal = parse("normal(1, 2)");
        let both = parse("uniform(0, 4) + normal(u0, 1)");
        let mut env = Env {
            k: 0,
            u: &[3.0, 0.0],
            p: &[],
            history: &history,
            random: Some(&mut rng),
        };
        assert_eq!(uniform.eval(&mut env), 0.0);
        assert_eq!(normal.eval(&mut env), 4.0);
        assert_eq!(both.eval(&mut env), 2.0 + 4.5);
        env.random = None;
        assert!(uniform.eval(&mut env).is_nan(), "no source: NaN");
        assert_eq!(rng.draws, 4);
    }

    #[test]
    fn context_restricts_k_lags_and_random() {
        let fault = ExprContext::fault_column(2, 1);
        assert_eq!(
            err("1 + k", &fault),
            ExprError::NotAllowed {
                what: "k",
                text: "k".into(),
                pos: 4
            }
        );
        assert_eq!(
            err("1 + k", &fault).to_string(),
            "k not allowed here: \"k\" at byte 4"
        );
        let e = err("2*uniform(0, 1)", &fault);
        assert_eq!(
            e.to_string(),
            "random functions not allowed here: \"uniform\" at byte 2"
        );
        assert!(matches!(
            err("normal(0, 1)", &fault),
            ExprError::NotAllowed {
                what: "random functions",
                ..
            }
        ));
        let no_lags = ExprContext {
            allow_lags: false,
            ..all()
        };
        assert_eq!(
            err("u0 - u0[ -1 ]", &no_lags).to_string(),
            "lags not allowed here: \"u0[ -1 ]\" at byte 5"
        );
        // [0] is not a lag.
        assert!(Expr::parse("u0[0]", &no_lags).is_ok());
        // The same sources are fine where allowed.
        for src in ["1 + k", "2*uniform(0, 1)", "normal(0, 1)", "u0 - u0[-1]"] {
            assert!(Expr::parse(src, &all()).is_ok(), "{src}");
        }
        assert!(Expr::parse("0.5*u0[-1] - p0", &fault).is_ok());
    }

    #[test]
    fn unknown_signals_name_the_text_and_what_exists() {
        let ctx = ExprContext::fault_column(2, 1);
        let e = err("0.5 * u7", &ctx);
        assert_eq!(
            e,
            ExprError::UnknownSignal {
                name: "u7".into(),
                pos: 6,
                hint: "the channel has 2 inputs: u0..u1".into()
            }
        );
        assert_eq!(
            e.to_string(),
            "unknown signal \"u7\" (the channel has 2 inputs: u0..u1)"
        );
        assert_eq!(
            err("p1", &ctx).to_string(),
            "unknown signal \"p1\" (the channel has 1 exogenous signal: p0)"
        );
        let none = ExprContext::fault_column(0, 0);
        assert_eq!(
            err("u0[-1]", &none).to_string(),
            "unknown signal \"u0\" (the channel has no inputs)"
        );
        assert_eq!(
            err("x + 1", &ctx).to_string(),
            "unknown signal \"x\" (known names: u0..u1, p0, pi, e)"
        );
        assert_eq!(
            err("K", &all()).to_string(),
            "unknown signal \"K\" (known names: u0..u1, p0..p2, k, pi, e)"
        );
        let e = err("u99999999999999999999999", &ctx);
        assert!(matches!(e, ExprError::UnknownSignal { pos: 0, .. }), "{e}");
    }

    #[test]
    fn unknown_functions_and_wrong_arity() {
        let ctx = ExprContext::fault_column(2, 1);
        let e = err("1 + foo(u0)", &ctx);
        assert_eq!(
            e.to_string(),
            "unknown function \"foo\" at byte 4 (known functions: \
             sin, cos, tan, exp, log, sqrt, abs, min, max, pow)"
        );
        assert!(
            err("ln(2)", &all()).to_string().contains("uniform, normal"),
            "random functions listed where allowed"
        );
        assert_eq!(
            err("min(1)", &ctx),
            ExprError::WrongArity {
                name: "min".into(),
                pos: 0,
                expected: 2,
                found: 1
            }
        );
        assert_eq!(
            err("2*sin(1, 2)", &ctx).to_string(),
            "function \"sin\" at byte 2 takes 1 argument, found 2"
        );
        assert_eq!(
            err("pow()", &ctx).to_string(),
            "function \"pow\" at byte 0 takes 2 arguments, found 0"
        );
        assert!(matches!(
            err("uniform(1)", &all()),
            ExprError::WrongArity { expected: 2, .. }
        ));
    }

    #[test]
    fn syntax_errors_point_at_the_token() {
        let ctx = all();
        for (src, pos, found) in [
            ("", 0, "end of expression"),
            ("1 +", 3, "end of expression"),
            ("(1", 2, "end of expression"),
            ("1 2", 2, "\"2\""),
            ("1)", 1, "\")\""),
            ("u0[-1.5]", 4, "\"1.5\""),
            ("u0[-1", 5, "end of expression"),
            ("u0[-k]", 4, "\"k\""),
            ("sin 1", 4, "\"1\""),
            ("sin(1,)", 6, "\")\""),
            ("1 # 2", 2, "\"#\""),
            ("2 * é", 4, "\"é\""),
            ("1 . 2", 2, "\".\""),
            ("2e", 1, "\"e\""),
            ("k[-1]", 1, "\"[\""),
            ("u0(1)", 2, "\"(\""),
            ("*2", 0, "\"*\""),
        ] {
            match err(src, &ctx) {
                ExprError::Syntax {
                    pos: p, found: f, ..
                } => assert_eq!((p, f.as_str()), (pos, found), "{src}"),
                e => panic!("{src}: {e}"),
            }
        }
        assert_eq!(
            err("(1 + 2", &ctx).to_string(),
            "syntax error at byte 6: expected an operator or \")\", found end of expression"
        );
    }

    #[test]
    fn lag_errors() {
        let ctx = all();
        assert_eq!(
            err("1 + u0[2]", &ctx),
            ExprError::PositiveLag {
                text: "u0[2]".into(),
                pos: 4
            }
        );
        assert!(
            err("p1[+1]", &ctx)
                .to_string()
                .starts_with("positive lag in \"p1[+1]\" at byte 0")
        );
        assert!(Expr::parse("u0[-10000]", &ctx).is_ok());
        assert_eq!(
            err("u0[-10001]", &ctx).to_string(),
            "lag too large in \"u0[-10001]\" at byte 0: at most 10000 samples back"
        );
        assert!(matches!(
            err("u0[-99999999999999999999999999]", &ctx),
            ExprError::LagTooLarge { .. }
        ));
        assert!(matches!(
            err("u0[99999999999999999999999999]", &ctx),
            ExprError::PositiveLag { .. }
        ));
    }

    #[test]
    fn length_and_depth_limits() {
        let ctx = all();
        let long = "1+".repeat(2100) + "1";
        assert_eq!(
            err(&long, &ctx),
            ExprError::TooLong {
                len: 4201,
                max: MAX_LEN
            }
        );
        assert!(
            err(&long, &ctx)
                .to_string()
                .contains("4201 bytes, the limit is 4096")
        );
        let nested = |n: usize| "(".repeat(n) + "u0" + &")".repeat(n);
        assert!(Expr::parse(&nested(MAX_DEPTH), &ctx).is_ok());
        assert_eq!(
            err(&nested(MAX_DEPTH + 1), &ctx),
            ExprError::TooDeep {
                text: "(".into(),
                pos: MAX_DEPTH,
                max: MAX_DEPTH
            }
        );
        assert!(
            err(&nested(2000), &ctx)
                .to_string()
                .contains("nested too deeply at byte 64")
        );
        let signs = "-".repeat(100) + "u0";
        assert!(matches!(err(&signs, &ctx), ExprError::TooDeep { .. }));
        let powers = "u0^".repeat(100) + "2";
        assert!(matches!(err(&powers, &ctx), ExprError::TooDeep { .. }));
        let calls = "sin(".repeat(100) + "u0" + &")".repeat(100);
        assert!(matches!(err(&calls, &ctx), ExprError::TooDeep { .. }));
    }

    /// Parses `src`, then evaluates it at k = 1, u = [1, 1] on a thread with a small
    /// stack (256 KiB, an eighth of a spawned thread's default; the worst case takes
    /// under 128 KiB unoptimised).
    fn eval_on_small_stack(src: String) -> f64 {
        let e = parse(&src);
        std::thread::Builder::new()
            .stack_size(256 * 1024)
            .spawn(move || {
                let history = SignalHistory::new(0, 0, 0);
                let mut env = Env {
                    k: 1,
                    u: &[1.0, 1.0],
                    p: &[],
                    history: &history,
                    random: None,
                };
                e.eval(&mut env)
            })
            .unwrap()
            .join()
            .unwrap()
    }

    #[test]
    fn longest_and_deepest_expressions_fit_a_small_stack() {
        // 2048 terms: one chain node, evaluated in a loop.
        let flat = "k+".repeat(2047) + "k";
        assert!(flat.len() <= MAX_LEN);
        assert_eq!(parse(&flat).nodes.len(), 2049);
        assert_eq!(eval_on_small_stack(flat), 2048.0);
        let products = "k*u0/u1*".repeat(400) + "k";
        assert_eq!(eval_on_small_stack(products), 1.0);
        // The deepest nestings the parser accepts, with chains at every level.
        let n = MAX_DEPTH - 1;
        let parens = "k+k*(".repeat(n) + "k" + &")".repeat(n);
        assert_eq!(eval_on_small_stack(parens), (n + 1) as f64);
        let calls = "k*abs(".repeat(n) + "k" + &")".repeat(n);
        assert_eq!(eval_on_small_stack(calls), 1.0);
        let signs = "k-".repeat(3) + &"-".repeat(n) + "k"; // 1 - 1 - 1 - (-1)
        assert_eq!(eval_on_small_stack(signs), 0.0);
        let powers = "k^".repeat(n) + "k";
        assert_eq!(eval_on_small_stack(powers), 1.0);
    }

    #[test]
    fn non_finite_constants_are_rejected() {
        let ctx = all();
        assert_eq!(
            err("2 * 1e999", &ctx),
            ExprError::NonFiniteConstant {
                text: "1e999".into(),
                pos: 4
            }
        );
        assert_eq!(
            err("u0 + 1/0", &ctx).to_string(),
            "\"1/0\" at byte 5 is not a finite number"
        );
        assert_eq!(
            err("log(0)", &ctx).to_string(),
            "\"log(0)\" at byte 0 is not a finite number"
        );
        assert!(matches!(
            err("u0 * exp(1000)", &ctx),
            ExprError::NonFiniteConstant { pos: 5, .. }
        ));
        assert!(matches!(
            err("sqrt(-1)", &ctx),
            ExprError::NonFiniteConstant { .. }
        ));
        // A tiny literal is fine (it underflows to 0).
        assert_eq!(parse("1e-999").constant_value(), Some(0.0));
    }

    #[test]
    fn source_display_and_clone() {
        let src = "  0.5*u0[-1] - p1 ";
        let e = parse(src);
        assert_eq!(e.source(), src);
        assert_eq!(e.to_string(), src);
        let c = e.clone();
        assert_eq!(c.source(), src);
        assert_eq!(c.max_lag(), 1);
    }

    /// A candidate fault function reads the estimated state `x<i>` and the time `t`
    /// (the paper's φ₁ and φ₂ at a state), only in its own context: elsewhere `x<i>`
    /// is unknown and `t` not allowed; an index past the model's states and a lagged
    /// state are refused.
    #[test]
    fn candidate_expressions_read_the_state_and_the_time() {
        let ctx = ExprContext::candidate(1, 5);
        let parse_all = |srcs: &[&str]| -> Vec<Expr> {
            srcs.iter().map(|s| Expr::parse(s, &ctx).unwrap()).collect()
        };
        let x = [0.1, 0.2, -0.3, 0.4, 1.2];
        let mut phi1 = ExprCandidate::new(parse_all(&["x1 + x2", "cos(x3)", "cos(0.5*x4)"]), 1);
        let mut out = [0.0; 3];
        phi1.evaluate(7.0, &x, &[2.0], &mut out);
        assert!(close(out[0], -0.1) && close(out[1], 0.4f64.cos()));
        assert!(close(out[2], 0.6f64.cos()));
        let mut phi2 = ExprCandidate::new(
            parse_all(&["x1 + x2", "20*exp(-abs(x3))", "sin(0.5*x4)"]),
            1,
        );
        phi2.evaluate(7.0, &x, &[2.0], &mut out);
        assert!(close(out[1], 20.0 * (-0.4f64).exp()) && close(out[2], 0.6f64.sin()));
        let mut mixed = ExprCandidate::new(parse_all(&["t*u0 + x0"]), 1);
        let mut two = [0.0; 2];
        mixed.evaluate(1.5, &x, &[2.0], &mut two);
        assert!(close(two[0], 3.1) && two[1].is_nan());
        assert_eq!(
            Expr::parse("x1 + x2", &ctx).unwrap().highest_state(),
            Some(2)
        );
        // Plain evaluation has no state: x<i> reads NaN.
        let e = Expr::parse("x0", &ctx).unwrap();
        assert!(
            e.eval(&mut Env {
                k: 0,
                u: &[],
                p: &[],
                history: &SignalHistory::new(0, 0, 0),
                random: None,
            })
            .is_nan()
        );
        let err5 = err("x5 + 1", &ctx).to_string();
        assert!(
            err5.contains("\"x5\"") && err5.contains("5 states: x0..x4"),
            "{err5}"
        );
        assert!(matches!(
            err("x0[-1]", &ctx),
            ExprError::NotAllowed { what: "lags", .. }
        ));
        assert!(matches!(
            err("k", &ctx),
            ExprError::NotAllowed { what: "k", .. }
        ));
        assert!(matches!(err("p0", &ctx), ExprError::UnknownSignal { .. }));
        let fault = ExprContext::fault_column(1, 1);
        let ex = err("2*x0", &fault).to_string();
        assert!(ex.contains("\"x0\"") && ex.contains("kernel"), "{ex}");
        assert_eq!(
            err("sin(t)", &fault).to_string(),
            "t not allowed here: \"t\" at byte 4"
        );
        assert!(matches!(
            err("t", &all()),
            ExprError::NotAllowed { what: "t", .. }
        ));
    }

    #[test]
    fn expr_column_through_the_column_fn_trait() {
        let ctx = ExprContext::fault_column(2, 2);
        let exprs = ["0.5*u0[-1] - p1", "2", "u1 * p0[-2]"]
            .iter()
            .map(|s| Expr::parse(s, &ctx).unwrap())
            .collect::<Vec<_>>();
        let column = ExprColumn::new(exprs, 2, 2);
        assert_eq!(column.len(), 3);
        assert!(!column.is_empty());
        assert_eq!(column.exprs()[1].constant_value(), Some(2.0));
        let mut f: Box<dyn ColumnFn> = Box::new(column);
        let system = SystemMatrices::zeros(Dims {
            states: 3,
            inputs: 2,
            outputs: 1,
            signals: 2,
        });
        let mut rows = Vec::new();
        for k in 0..4u64 {
            let u = [k as f64, 1.0];
            let p = [10.0 * k as f64, 1.0];
            let mut out = [f64::NAN; 3];
            f.evaluate(k, &Signals { u: &u, p: &p }, &system, &mut out);
            rows.push(out);
        }
        assert_eq!(
            rows,
            vec![
                [-1.0, 2.0, 0.0],
                [-1.0, 2.0, 0.0],
                [-0.5, 2.0, 0.0],
                [0.0, 2.0, 10.0],
            ]
        );
        // A longer output than the column: the extra entries are NaN.
        let mut out = [0.0; 4];
        f.evaluate(
            4,
            &Signals {
                u: &[0.0, 1.0],
                p: &[0.0, 0.0],
            },
            &system,
            &mut out,
        );
        assert!(out[3].is_nan());
        assert_eq!(out[2], 20.0);
    }

    fn check_never_panics(src: &str) {
        let strict = ExprContext::fault_column(1, 1);
        let empty = ExprContext {
            inputs: 0,
            signals: 0,
            allow_k: false,
            allow_lags: false,
            allow_random: false,
            states: 0,
            allow_t: false,
        };
        let mut history = SignalHistory::new(3, 2, 3);
        history.push(&[1.0, 2.0], &[3.0, 4.0, 5.0]);
        for ctx in [all(), strict, empty] {
            match Expr::parse(src, &ctx) {
                Ok(e) => {
                    assert_eq!(e.source(), src);
                    let mut rng = Fixed::default();
                    let mut env = Env {
                        k: 5,
                        u: &[0.5, -1.0],
                        p: &[0.0, 2.0, 3.0],
                        history: &history,
                        random: Some(&mut rng),
                    };
                    let v = e.eval(&mut env);
                    if let Some(c) = e.constant_value() {
                        assert!(c.is_finite());
                        assert_eq!(v.to_bits(), c.to_bits());
                    }
                    let _ = e.max_lag();
                }
                Err(e) => {
                    let _ = e.to_string();
                }
            }
        }
    }

    const FRAGMENTS: &[&str] = &[
        "u0", "p1", "[", "-3", "]", "(", ")", "+", "*", "/", "sin", "1.5", "k", ",", " ", "-", "^",
        "0", "e", "1e", "pi", "min", "uniform", "u9", ".", "[0]", "[-1]",
    ];

    /// A generated expression tree, rendered to source and evaluated directly.
    #[derive(Debug, Clone)]
    enum Tree {
        Num(f64),
        U(usize),
        P(usize),
        K,
        LagU(usize, usize),
        Neg(Box<Tree>),
        Bin(char, Box<Tree>, Box<Tree>),
        Call(&'static str, Vec<Tree>),
    }

    const U: [f64; 2] = [0.5, -1.0];
    const P: [f64; 3] = [0.0, 2.0, 3.0];
    const PAST_U0: [f64; 3] = [7.0, 8.0, 9.0]; // u0 at k − 1, k − 2, k − 3

    impl Tree {
        /// The reference value, with the same f64 operations.
        fn value(&self) -> f64 {
            match self {
                Tree::Num(v) => *v,
                Tree::U(i) => U[*i],
                Tree::P(i) => P[*i],
                Tree::K => 5.0,
                Tree::LagU(i, lag) => [PAST_U0[*lag - 1], 0.0][*i],
                Tree::Neg(a) => -a.value(),
                Tree::Bin(op, a, b) => {
                    let (x, y) = (a.value(), b.value());
                    match op {
                        '+' => x + y,
                        '-' => x - y,
                        '*' => x * y,
                        '/' => x / y,
                        _ => x.powf(y),
                    }
                }
                Tree::Call(f, args) => {
                    let x = args[0].value();
                    match *f {
                        "sin" => x.sin(),
                        "exp" => x.exp(),
                        "log" => x.ln(),
                        "abs" => x.abs(),
                        "min" => x.min(args[1].value()),
                        "max" => x.max(args[1].value()),
                        _ => x.powf(args[1].value()),
                    }
                }
            }
        }

        /// The source: parenthesised, except that a left operand of the same
        /// precedence is left bare so that chains such as `a - b + c` appear.
        fn render(&self, bare: bool, space: &str) -> String {
            let level = |t: &Tree| match t {
                Tree::Bin('+' | '-', ..) => 1,
                Tree::Bin('*' | '/', ..) => 2,
                _ => 0,
            };
            match self {
                Tree::Num(v) => format!("{v:?}"),
                Tree::U(i) => format!("u{i}"),
                Tree::P(i) => format!("p{i}"),
                Tree::K => "k".into(),
                Tree::LagU(i, lag) => format!("u{i}[{space}-{lag}{space}]"),
                Tree::Neg(a) => format!("(-{space}{})", a.render(false, space)),
                Tree::Bin(op, a, b) => {
                    let left_bare = level(self) != 0 && level(a) == level(self);
                    let inner = format!(
                        "{}{space}{op}{space}{}",
                        a.render(left_bare, space),
                        b.render(false, space)
                    );
                    if bare { inner } else { format!("({inner})") }
                }
                Tree::Call(f, args) => {
                    let args: Vec<String> = args.iter().map(|a| a.render(false, space)).collect();
                    format!("{f}({})", args.join(&format!(",{space}")))
                }
            }
        }
    }

    fn tree() -> impl Strategy<Value = Tree> {
        let leaf = prop_oneof![
            proptest::sample::select(&[0.0, 1.0, 2.5, 1e-3, 1e10, 3.0][..]).prop_map(Tree::Num),
            (0..2usize).prop_map(Tree::U),
            (0..3usize).prop_map(Tree::P),
            Just(Tree::K),
            (1..=3usize).prop_map(|lag| Tree::LagU(0, lag)),
        ];
        leaf.prop_recursive(6, 48, 2, |inner| {
            prop_oneof![
                inner.clone().prop_map(|a| Tree::Neg(Box::new(a))),
                (
                    proptest::sample::select(&['+', '-', '*', '/', '^'][..]),
                    inner.clone(),
                    inner.clone()
                )
                    .prop_map(|(op, a, b)| Tree::Bin(op, Box::new(a), Box::new(b))),
                (
                    proptest::sample::select(&["sin", "exp", "log", "abs"][..]),
                    inner.clone()
                )
                    .prop_map(|(f, a)| Tree::Call(f, vec![a])),
                (
                    proptest::sample::select(&["min", "max", "pow"][..]),
                    inner.clone(),
                    inner
                )
                    .prop_map(|(f, a, b)| Tree::Call(f, vec![a, b])),
            ]
        })
    }

    proptest! {
        #[test]
        fn generated_expressions_match_a_reference_evaluation(
            t in tree(),
            space in proptest::sample::select(&["", " ", " \t"][..]),
        ) {
            let src = t.render(true, space);
            let reference = t.value();
            let mut history = SignalHistory::new(3, 2, 3);
            for past in PAST_U0.iter().rev() {
                history.push(&[*past, 0.0], &[0.0; 3]);
            }
            match Expr::parse(&src, &all()) {
                Ok(e) => {
                    let mut env = Env {
                        k: 5,
                        u: &U,
                        p: &P,
                        history: &history,
                        random: None,
                    };
                    let v = e.eval(&mut env);
                    prop_assert!(
                        v.to_bits() == reference.to_bits() || (v.is_nan() && reference.is_nan()),
                        "{src}: {v} != {reference}"
                    );
                }
                // A constant sub-expression that overflows, e.g. exp(1e10).
                Err(ExprError::NonFiniteConstant { .. }) => {}
                Err(e) => prop_assert!(false, "{src}: {e}"),
            }
        }

        #[test]
        fn arbitrary_strings_never_panic(
            parts in proptest::collection::vec(proptest::sample::select(FRAGMENTS), 0..40)
        ) {
            check_never_panics(&parts.concat());
        }

        #[test]
        fn arbitrary_unicode_never_panics(src in "(?s).{0,200}") {
            check_never_panics(&src);
        }
    }
}
