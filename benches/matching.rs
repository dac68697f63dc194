//! Benchmarks (divan): run with `cargo bench --bench matching`.

fn main() {
    divan::main();
}
