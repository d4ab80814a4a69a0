//! The lexer and the recursive-descent parser of [`super::Expr`]: source text to the
//! expression's nodes, every error naming the offending text and its position.

use super::{
    Expr, ExprContext, ExprError, FUNCTIONS, FUNCTIONS_RANDOM, Func, MAX_DEPTH, MAX_LAG, Node, Op1,
    Op2,
};

/// Parses `src` (at most [`super::MAX_LEN`] bytes, checked by the caller) in `ctx`.
pub(super) fn parse(src: &str, ctx: &ExprContext) -> Result<Expr, ExprError> {
    let tokens = lex(src)?;
    let mut parser = Parser {
        src,
        tokens,
        at: 0,
        depth: 0,
        ctx: *ctx,
        nodes: Vec::new(),
        links: Vec::new(),
        max_lag: 0,
        uses_random: false,
        uses_k: false,
        highest_input: None,
        highest_signal: None,
        highest_state: None,
    };
    let root = parser.parse_expr()?;
    let end = parser.peek();
    if end.tok != Tok::End {
        return Err(parser.syntax(end, "an operator or the end of the expression"));
    }
    Ok(Expr {
        source: src.to_owned(),
        nodes: parser.nodes,
        links: parser.links,
        root: root.node,
        max_lag: parser.max_lag,
        uses_random: parser.uses_random,
        uses_k: parser.uses_k,
        highest_input: parser.highest_input,
        highest_signal: parser.highest_signal,
        highest_state: parser.highest_state,
    })
}

// ---------------------------------------------------------------------------------
// Lexer

#[derive(Debug, Clone, Copy, PartialEq)]
enum Tok {
    Num(f64),
    Ident,
    LParen,
    RParen,
    LBracket,
    RBracket,
    Comma,
    Plus,
    Minus,
    Star,
    Slash,
    Caret,
    End,
}

#[derive(Debug, Clone, Copy)]
struct Token {
    tok: Tok,
    start: usize,
    end: usize,
}

fn skip_digits(bytes: &[u8], mut i: usize) -> usize {
    while bytes.get(i).is_some_and(u8::is_ascii_digit) {
        i += 1;
    }
    i
}

fn quoted(text: &str) -> String {
    format!("\"{}\"", text.escape_debug())
}

fn lex(src: &str) -> Result<Vec<Token>, ExprError> {
    let bytes = src.as_bytes();
    let mut tokens = Vec::new();
    let mut i = 0;
    while let Some(&b) = bytes.get(i) {
        let start = i;
        let tok = match b {
            b' ' | b'\t' | b'\n' | b'\r' => {
                i += 1;
                continue;
            }
            b'0'..=b'9' | b'.' => {
                let int_end = skip_digits(bytes, i);
                let mut j = int_end;
                let mut fraction = false;
                if bytes.get(j) == Some(&b'.') {
                    let frac_end = skip_digits(bytes, j + 1);
                    fraction = frac_end > j + 1;
                    j = frac_end;
                }
                if int_end == start && !fraction {
                    return Err(ExprError::Syntax {
                        pos: start,
                        expected: "a digit before or after \".\"",
                        found: quoted("."),
                    });
                }
                if matches!(bytes.get(j), Some(b'e' | b'E')) {
                    let mut e = j + 1;
                    if matches!(bytes.get(e), Some(b'+' | b'-')) {
                        e += 1;
                    }
                    let exp_end = skip_digits(bytes, e);
                    if exp_end > e {
                        j = exp_end;
                    }
                }
                i = j;
                let text = src.get(start..j).unwrap_or_default();
                match text.parse::<f64>() {
                    Ok(v) if v.is_finite() => Tok::Num(v),
                    Ok(_) => {
                        return Err(ExprError::NonFiniteConstant {
                            text: text.to_owned(),
                            pos: start,
                        });
                    }
                    Err(_) => {
                        return Err(ExprError::Syntax {
                            pos: start,
                            expected: "a number",
                            found: quoted(text),
                        });
                    }
                }
            }
            b'a'..=b'z' | b'A'..=b'Z' | b'_' => {
                while bytes
                    .get(i)
                    .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
                {
                    i += 1;
                }
                Tok::Ident
            }
            _ => {
                let tok = match b {
                    b'(' => Tok::LParen,
                    b')' => Tok::RParen,
                    b'[' => Tok::LBracket,
                    b']' => Tok::RBracket,
                    b',' => Tok::Comma,
                    b'+' => Tok::Plus,
                    b'-' => Tok::Minus,
                    b'*' => Tok::Star,
                    b'/' => Tok::Slash,
                    b'^' => Tok::Caret,
                    _ => {
                        let c = src
                            .get(start..)
                            .and_then(|s| s.chars().next())
                            .unwrap_or(char::REPLACEMENT_CHARACTER);
                        return Err(ExprError::Syntax {
                            pos: start,
                            expected: "a number, a name, an operator or a parenthesis",
                            found: quoted(c.encode_utf8(&mut [0; 4])),
                        });
                    }
                };
                i += 1;
                tok
            }
        };
        tokens.push(Token { tok, start, end: i });
    }
    tokens.push(Token {
        tok: Tok::End,
        start: src.len(),
        end: src.len(),
    });
    Ok(tokens)
}

// ---------------------------------------------------------------------------------
// Parser

/// A parsed sub-expression: its node and its byte span in the source.
#[derive(Debug, Clone, Copy)]
struct Sub {
    node: usize,
    start: usize,
    end: usize,
}

struct Parser<'a> {
    src: &'a str,
    tokens: Vec<Token>,
    at: usize,
    depth: usize,
    ctx: ExprContext,
    nodes: Vec<Node>,
    links: Vec<(Op2, usize)>,
    max_lag: usize,
    uses_random: bool,
    uses_k: bool,
    highest_input: Option<usize>,
    highest_signal: Option<usize>,
    highest_state: Option<usize>,
}

impl<'a> Parser<'a> {
    fn peek(&self) -> Token {
        self.tokens.get(self.at).copied().unwrap_or(Token {
            tok: Tok::End,
            start: self.src.len(),
            end: self.src.len(),
        })
    }

    fn bump(&mut self) -> Token {
        let t = self.peek();
        if t.tok != Tok::End {
            self.at += 1;
        }
        t
    }

    fn text(&self, start: usize, end: usize) -> &'a str {
        self.src.get(start..end).unwrap_or_default()
    }

    fn syntax(&self, t: Token, expected: &'static str) -> ExprError {
        let found = if t.tok == Tok::End {
            "end of expression".to_owned()
        } else {
            quoted(self.text(t.start, t.end))
        };
        ExprError::Syntax {
            pos: t.start,
            expected,
            found,
        }
    }

    fn expect(&mut self, tok: Tok, expected: &'static str) -> Result<Token, ExprError> {
        let t = self.peek();
        if t.tok == tok {
            Ok(self.bump())
        } else {
            Err(self.syntax(t, expected))
        }
    }

    /// Enters one nesting level opened by `t`.
    fn enter(&mut self, t: Token) -> Result<(), ExprError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(ExprError::TooDeep {
                text: self.text(t.start, t.end).to_owned(),
                pos: t.start,
                max: MAX_DEPTH,
            });
        }
        Ok(())
    }

    fn leave(&mut self) {
        self.depth = self.depth.saturating_sub(1);
    }

    fn constant(&self, i: usize) -> Option<f64> {
        match self.nodes.get(i) {
            Some(Node::Const(v)) => Some(*v),
            _ => None,
        }
    }

    /// Pushes `node` spanning `start..end`, folding it when its children are constants.
    fn push(&mut self, node: Node, start: usize, end: usize) -> Result<Sub, ExprError> {
        let folded = match node {
            Node::Unary(op, a) => self.constant(a).map(|x| (op.apply(x), a, 1)),
            Node::Binary(op, a, b) => match (self.constant(a), self.constant(b)) {
                (Some(x), Some(y)) => Some((op.apply(x, y), a, 2)),
                _ => None,
            },
            Node::Const(v) => Some((v, self.nodes.len(), 0)),
            _ => None,
        };
        match folded {
            Some((v, first, count)) => {
                if !v.is_finite() {
                    return Err(ExprError::NonFiniteConstant {
                        text: self.text(start, end).to_owned(),
                        pos: start,
                    });
                }
                // The constant children are the arena's last nodes (each folded
                // sub-expression is a single node): drop them.
                if first + count == self.nodes.len() {
                    self.nodes.truncate(first);
                }
                self.nodes.push(Node::Const(v));
            }
            None => self.nodes.push(node),
        }
        Ok(Sub {
            node: self.nodes.len() - 1,
            start,
            end,
        })
    }

    fn parse_expr(&mut self) -> Result<Sub, ExprError> {
        self.parse_chain(true)
    }

    fn parse_term(&mut self) -> Result<Sub, ExprError> {
        self.parse_chain(false)
    }

    /// A left-associative chain `a op b op c …` of `+ -` (`additive`) or of `* /`
    /// operands. The constant prefix folds; the rest becomes one [`Node::Chain`], which
    /// evaluation iterates, so a long sum does not deepen the recursion.
    fn parse_chain(&mut self, additive: bool) -> Result<Sub, ExprError> {
        let mut lhs = self.parse_operand(additive)?;
        let mut links = Vec::new();
        let mut end = lhs.end;
        loop {
            let op = match (additive, self.peek().tok) {
                (true, Tok::Plus) => Op2::Add,
                (true, Tok::Minus) => Op2::Sub,
                (false, Tok::Star) => Op2::Mul,
                (false, Tok::Slash) => Op2::Div,
                _ => break,
            };
            self.bump();
            let rhs = self.parse_operand(additive)?;
            let foldable = self.constant(lhs.node).is_some() && self.constant(rhs.node).is_some();
            if links.is_empty() && foldable {
                lhs = self.push(Node::Binary(op, lhs.node, rhs.node), lhs.start, rhs.end)?;
            } else {
                links.push((op, rhs.node));
            }
            end = rhs.end;
        }
        match links.as_slice() {
            [] => Ok(lhs),
            [(op, rhs)] => self.push(Node::Binary(*op, lhs.node, *rhs), lhs.start, end),
            _ => {
                let start = self.links.len();
                self.links.extend_from_slice(&links);
                let chain = Node::Chain {
                    first: lhs.node,
                    start,
                    len: links.len(),
                };
                self.push(chain, lhs.start, end)
            }
        }
    }

    fn parse_operand(&mut self, additive: bool) -> Result<Sub, ExprError> {
        if additive {
            self.parse_term()
        } else {
            self.parse_unary()
        }
    }

    fn parse_unary(&mut self) -> Result<Sub, ExprError> {
        let t = self.peek();
        match t.tok {
            Tok::Minus | Tok::Plus => {
                self.bump();
                self.enter(t)?;
                let inner = self.parse_unary()?;
                self.leave();
                if t.tok == Tok::Minus {
                    self.push(Node::Unary(Op1::Neg, inner.node), t.start, inner.end)
                } else {
                    Ok(Sub {
                        start: t.start,
                        ..inner
                    })
                }
            }
            _ => self.parse_power(),
        }
    }

    fn parse_power(&mut self) -> Result<Sub, ExprError> {
        let base = self.parse_primary()?;
        let t = self.peek();
        if t.tok != Tok::Caret {
            return Ok(base);
        }
        self.bump();
        self.enter(t)?;
        let exponent = self.parse_unary()?;
        self.leave();
        self.push(
            Node::Binary(Op2::Pow, base.node, exponent.node),
            base.start,
            exponent.end,
        )
    }

    fn parse_primary(&mut self) -> Result<Sub, ExprError> {
        let t = self.peek();
        match t.tok {
            Tok::Num(v) => {
                self.bump();
                self.push(Node::Const(v), t.start, t.end)
            }
            Tok::LParen => {
                self.bump();
                self.enter(t)?;
                let inner = self.parse_expr()?;
                let close = self.expect(Tok::RParen, "an operator or \")\"")?;
                self.leave();
                Ok(Sub {
                    node: inner.node,
                    start: t.start,
                    end: close.end,
                })
            }
            Tok::Ident => {
                self.bump();
                self.parse_name(t)
            }
            _ => Err(self.syntax(t, "a number, a name, \"(\" or a sign")),
        }
    }

    fn parse_name(&mut self, t: Token) -> Result<Sub, ExprError> {
        let name = self.text(t.start, t.end);
        match name {
            "pi" => return self.push(Node::Const(std::f64::consts::PI), t.start, t.end),
            "e" => return self.push(Node::Const(std::f64::consts::E), t.start, t.end),
            "k" => {
                if !self.ctx.allow_k {
                    return Err(ExprError::NotAllowed {
                        what: "k",
                        text: "k".to_owned(),
                        pos: t.start,
                    });
                }
                self.uses_k = true;
                return self.push(Node::K, t.start, t.end);
            }
            "t" => {
                if !self.ctx.allow_t {
                    return Err(ExprError::NotAllowed {
                        what: "t",
                        text: "t".to_owned(),
                        pos: t.start,
                    });
                }
                return self.push(Node::T, t.start, t.end);
            }
            _ => {}
        }
        if let Some(index) = state_variable(name) {
            return self.parse_state(t, index);
        }
        if let Some(f) = Func::lookup(name) {
            return self.parse_call(t, f);
        }
        if let Some((is_input, index)) = variable(name) {
            return self.parse_variable(t, is_input, index);
        }
        if self.peek().tok == Tok::LParen {
            return Err(ExprError::UnknownFunction {
                name: name.to_owned(),
                pos: t.start,
                known: if self.ctx.allow_random {
                    FUNCTIONS_RANDOM
                } else {
                    FUNCTIONS
                },
            });
        }
        Err(ExprError::UnknownSignal {
            name: name.to_owned(),
            pos: t.start,
            hint: self.known_names(),
        })
    }

    fn known_names(&self) -> String {
        let mut names = Vec::new();
        match self.ctx.inputs {
            0 => {}
            1 => names.push("u0".to_owned()),
            n => names.push(format!("u0..u{}", n - 1)),
        }
        match self.ctx.signals {
            0 => {}
            1 => names.push("p0".to_owned()),
            n => names.push(format!("p0..p{}", n - 1)),
        }
        match self.ctx.states {
            0 => {}
            1 => names.push("x0".to_owned()),
            n => names.push(format!("x0..x{}", n - 1)),
        }
        if self.ctx.allow_k {
            names.push("k".to_owned());
        }
        if self.ctx.allow_t {
            names.push("t".to_owned());
        }
        names.push("pi".to_owned());
        names.push("e".to_owned());
        format!("known names: {}", names.join(", "))
    }

    fn parse_variable(
        &mut self,
        t: Token,
        is_input: bool,
        index: Option<usize>,
    ) -> Result<Sub, ExprError> {
        let name = self.text(t.start, t.end);
        let (count, noun, letter) = if is_input {
            (self.ctx.inputs, "input", 'u')
        } else {
            (self.ctx.signals, "exogenous signal", 'p')
        };
        let index = match index {
            Some(i) if i < count => i,
            _ => {
                let hint = match count {
                    0 => format!("the channel has no {noun}s"),
                    1 => format!("the channel has 1 {noun}: {letter}0"),
                    n => format!("the channel has {n} {noun}s: {letter}0..{letter}{}", n - 1),
                };
                return Err(ExprError::UnknownSignal {
                    name: name.to_owned(),
                    pos: t.start,
                    hint,
                });
            }
        };
        let (lag, end) = if self.peek().tok == Tok::LBracket {
            self.parse_lag(t)?
        } else {
            (0, t.end)
        };
        let node = match (is_input, lag) {
            (true, 0) => Node::Input(index),
            (false, 0) => Node::Signal(index),
            (true, lag) => Node::LagInput { index, lag },
            (false, lag) => Node::LagSignal { index, lag },
        };
        if is_input {
            self.highest_input = self.highest_input.max(Some(index));
        } else {
            self.highest_signal = self.highest_signal.max(Some(index));
        }
        self.max_lag = self.max_lag.max(lag);
        self.push(node, t.start, end)
    }

    /// `x<i>`: the estimated state i, where the context has states; never lagged.
    fn parse_state(&mut self, t: Token, index: Option<usize>) -> Result<Sub, ExprError> {
        let name = self.text(t.start, t.end);
        let count = self.ctx.states;
        let index = match index {
            Some(i) if i < count => i,
            _ => {
                let hint = match count {
                    0 => "the state x<i> is read only by a candidate fault function of the \
                          `kernel` detector"
                        .to_owned(),
                    1 => "the model has 1 state: x0".to_owned(),
                    n => format!("the model has {n} states: x0..x{}", n - 1),
                };
                return Err(ExprError::UnknownSignal {
                    name: name.to_owned(),
                    pos: t.start,
                    hint,
                });
            }
        };
        if self.peek().tok == Tok::LBracket {
            return Err(ExprError::NotAllowed {
                what: "lags",
                text: name.to_owned(),
                pos: t.start,
            });
        }
        self.highest_state = self.highest_state.max(Some(index));
        self.push(Node::State(index), t.start, t.end)
    }

    /// Parses `[-n]` after the variable `var`; returns the lag and the span's end.
    fn parse_lag(&mut self, var: Token) -> Result<(usize, usize), ExprError> {
        self.bump(); // "["
        let sign = self.peek();
        let negative = match sign.tok {
            Tok::Minus => {
                self.bump();
                true
            }
            Tok::Plus => {
                self.bump();
                false
            }
            _ => false,
        };
        let n = self.peek();
        let digits = self.text(n.start, n.end);
        if !matches!(n.tok, Tok::Num(_)) || !digits.bytes().all(|b| b.is_ascii_digit()) {
            return Err(self.syntax(n, "an integer lag such as -1"));
        }
        self.bump();
        let close = self.expect(Tok::RBracket, "\"]\" after the lag")?;
        let text = self.text(var.start, close.end).to_owned();
        let value = digits.parse::<usize>().ok();
        if value != Some(0) && !negative {
            return Err(ExprError::PositiveLag {
                text,
                pos: var.start,
            });
        }
        let lag = match value {
            Some(lag) if lag <= MAX_LAG => lag,
            _ => {
                return Err(ExprError::LagTooLarge {
                    text,
                    pos: var.start,
                    max: MAX_LAG,
                });
            }
        };
        if lag > 0 && !self.ctx.allow_lags {
            return Err(ExprError::NotAllowed {
                what: "lags",
                text,
                pos: var.start,
            });
        }
        Ok((lag, close.end))
    }

    fn parse_call(&mut self, t: Token, f: Func) -> Result<Sub, ExprError> {
        let name = self.text(t.start, t.end).to_owned();
        if f.is_random() && !self.ctx.allow_random {
            return Err(ExprError::NotAllowed {
                what: "random functions",
                text: name,
                pos: t.start,
            });
        }
        let open = self.expect(Tok::LParen, "\"(\" after the function name")?;
        self.enter(open)?;
        let mut args = Vec::new();
        if self.peek().tok != Tok::RParen {
            loop {
                args.push(self.parse_expr()?);
                if self.peek().tok != Tok::Comma {
                    break;
                }
                self.bump();
            }
        }
        let close = self.expect(Tok::RParen, "\",\", \")\" or an operator")?;
        self.leave();
        let node = match (f, args.as_slice()) {
            (Func::One(op), [a]) => Node::Unary(op, a.node),
            (Func::Two(op), [a, b]) => Node::Binary(op, a.node, b.node),
            (Func::Uniform, [a, b]) => Node::Uniform(a.node, b.node),
            (Func::Normal, [a, b]) => Node::Normal(a.node, b.node),
            _ => {
                return Err(ExprError::WrongArity {
                    name,
                    pos: t.start,
                    expected: f.arity(),
                    found: args.len(),
                });
            }
        };
        if f.is_random() {
            self.uses_random = true;
        }
        self.push(node, t.start, close.end)
    }
}

/// `x<digits>` → the state index (`None` when it overflows); `None` for other names.
fn state_variable(name: &str) -> Option<Option<usize>> {
    let digits = name.strip_prefix('x')?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some(digits.parse::<usize>().ok())
}

/// `u<digits>` → (true, index), `p<digits>` → (false, index); the index is `None` when
/// it overflows.
fn variable(name: &str) -> Option<(bool, Option<usize>)> {
    let is_input = match name.as_bytes().first() {
        Some(b'u') => true,
        Some(b'p') => false,
        _ => return None,
    };
    let digits = name.get(1..)?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((is_input, digits.parse::<usize>().ok()))
}
