//! Benchmarks (divan): run with `cargo bench --bench level`.

fn main() {
    divan::main();
}
