//! Benchmarks (divan): run with `cargo bench --bench simulate`.

fn main() {
    divan::main();
}
