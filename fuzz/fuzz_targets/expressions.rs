//! Fault-column, simulation and candidate fault function expressions: parsing any
//! text, then evaluating what parses on finite and extreme signals (and, for a
//! candidate of the `kernel` detector, states and times), never panics.
#![no_main]

use glrmon_spec::expr::{Env, Expr, ExprContext, SignalHistory, StateEnv};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let ctx = ExprContext {
        inputs: 2,
        signals: 1,
        allow_k: true,
        allow_lags: true,
        allow_random: false,
        states: 0,
        allow_t: false,
    };
    if let Ok(expr) = Expr::parse(text, &ctx) {
        let history = SignalHistory::new(4, 2, 1);
        for (u, p) in [([0.0, 1.0], [2.0]), ([f64::MAX, -1e308], [1e-308])] {
            let _ = expr.eval(&mut Env {
                k: u64::MAX,
                u: &u,
                p: &p,
                history: &history,
                random: None,
            });
        }
    }
    if let Ok(expr) = Expr::parse(text, &ExprContext::candidate(2, 3)) {
        let history = SignalHistory::new(0, 2, 0);
        for (u, x, t) in [
            ([0.0, 1.0], [0.5, -2.0, 3.0], 0.0),
            ([f64::MAX, -1e308], [f64::MAX, -0.0, 1e-308], 1e300),
        ] {
            let _ = expr.eval_with_state(
                &mut Env {
                    k: 0,
                    u: &u,
                    p: &[],
                    history: &history,
                    random: None,
                },
                StateEnv { x: &x, t },
            );
        }
    }
});
