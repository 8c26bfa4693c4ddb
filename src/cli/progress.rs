//! The progress bar of a long command, drawn on stderr only when it is a terminal.

/// A progress bar of `len` steps (a spinner when 0) with the elapsed time, on stderr when it
/// is a terminal; nothing otherwise, so that piped output stays clean.
pub fn progress(len: u64, msg: &str) -> indicatif::ProgressBar {
    let (bar, template) = if len == 0 {
        (
            indicatif::ProgressBar::new_spinner(),
            "{spinner} {elapsed} {msg}",
        )
    } else {
        (
            indicatif::ProgressBar::new(len),
            "{spinner} {elapsed} [{bar:30}] {pos}/{len} {msg}",
        )
    };
    bar.set_style(indicatif::ProgressStyle::with_template(template).expect("valid template"));
    bar.set_message(msg.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(100));
    bar
}
