//! Progress on standard error for runs that can take more than a second (issue 25: `eval
//! accuracy --poses 1000` ran 29 s and `match` on a 4,791-scan log 5 s without a word).
//! indicatif draws to standard error only when it is a terminal, so pipes, files and the tests
//! see nothing of it; a bar is cleared when its run ends, leaving only the run's own messages.

use indicatif::{ProgressBar, ProgressStyle};
use std::time::Duration;

/// Redraws per second at most: often enough to look alive, rare enough to cost nothing.
const TICK: Duration = Duration::from_millis(120);

/// A counter for a stream of unknown length: `level: 1,234 poses (2s)`.
pub(crate) fn counter(what: &str, unit: &str) -> ProgressBar {
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "{{spinner}} {{msg}}: {{human_pos}} {unit} ({{elapsed}})"
        ))
        .expect("static template"),
    );
    bar.set_message(what.to_string());
    bar.enable_steady_tick(TICK);
    bar
}

/// A spinner for one long step whose progress is not counted (a whole log matched by the
/// library): `eval real: intel.log (3s)`.
pub(crate) fn spinner(what: &str) -> ProgressBar {
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} ({elapsed})").expect("static template"),
    );
    bar.set_message(what.to_string());
    bar.enable_steady_tick(TICK);
    bar
}
