//! Fault-column and simulation expressions: parsing any text, then evaluating what
//! parses on finite and extreme signals, never panics.
#![no_main]

use glrmon_spec::expr::{Env, Expr, ExprContext, SignalHistory};
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
});
