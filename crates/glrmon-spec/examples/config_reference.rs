//! Prints docs/CONFIG.md (`make config-doc` writes it):
//! `cargo run -q -p glrmon-spec --example config_reference > docs/CONFIG.md`.

fn main() {
    print!("{}", glrmon_spec::reference::config_reference());
}
