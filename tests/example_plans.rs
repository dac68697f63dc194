//! The shipped floor plans are strict JSON (no comments), so any tool that reads `.wall` files
//! reads ours, and each one is a valid plan.

use levelscan::formats::wall::parse_plan;

#[test]
fn example_plans_are_strict_json_and_valid_plans() {
    for (dir, at_least) in [
        ("examples/plans", 5),
        ("examples/plans/holdout", 5),
        ("examples/plans/unseen", 3),
        ("examples/plans/halls", 3),
    ] {
        assert_plans_in(dir, at_least);
    }
}

fn assert_plans_in(dir: &str, at_least: usize) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("wall") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let strict: Result<serde_json::Value, _> = serde_json::from_str(&text);
        assert!(strict.is_ok(), "{} is not strict JSON", path.display());
        let plan = parse_plan(&text, &path.display().to_string()).unwrap();
        assert!(!plan.walls.is_empty());
        seen += 1;
    }
    assert!(seen >= at_least, "only {seen} plans in {}", dir.display());
}
