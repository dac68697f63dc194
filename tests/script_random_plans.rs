//! `scripts/random_plans.py` end to end: the plans it draws are valid `.wall` files with free
//! space for random poses (columns built into walls included), each the same for its seed
//! whatever the count, and `eval accuracy` runs over them. Needs `python3` (standard library
//! only; `LEVELSCAN_PYTHON` when set); skipped without one unless `LEVELSCAN_REQUIRE_INTEROP=1`.

mod cli_support;
use cli_support::*;

use std::path::Path;
use std::process::Command;

fn draw(python: &str, dir: &Path, count: &str, seed: &str) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/random_plans.py");
    let out = Command::new(python)
        .arg(&script)
        .arg(dir)
        .args(["--count", count, "--seed", seed])
        .output()
        .unwrap();
    assert_ran(&out);
}

#[test]
fn random_plans_have_free_space_and_do_not_depend_on_the_count() {
    let Some(python) = python_or_skip("script_random_plans") else {
        return;
    };
    let dir = TempDir::new("random_plans");
    let (many, one) = (dir.0.join("many"), dir.0.join("one"));
    draw(&python, &many, "12", "3000");
    draw(&python, &one, "1", "3007");
    let read = |p: &Path| std::fs::read(p).unwrap();
    assert_eq!(
        read(&many.join("plan_3007.wall")),
        read(&one.join("plan_3007.wall"))
    );
    let mut plans: Vec<_> = std::fs::read_dir(&many)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    plans.sort();
    assert_eq!(plans.len(), 12);
    for plan in &plans {
        let out = bin()
            .arg("simulate")
            .arg(plan)
            .args(["--random", "4", "--scans", "3"])
            .output()
            .unwrap();
        assert_eq!(records(&out).len(), 12, "{}", plan.display());
    }
    let out = bin()
        .args(["eval", "accuracy"])
        .args(&plans)
        .args([
            "--poses",
            "2",
            "--scans",
            "3",
            "--sigma",
            "0.01",
            "--estimator",
            "robust",
        ])
        .output()
        .unwrap();
    assert_ran(&out);
    // One cell over every plan's two poses: "leveled" reads k/24.
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("/24 ("), "{table}");
}
