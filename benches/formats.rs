//! Benchmarks (divan): run with `cargo bench --bench formats`.

fn main() {
    divan::main();
}
