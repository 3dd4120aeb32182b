//! The progress bar of every long loop (simulate, extract, process, gap
//! validate): one style, hidden unless asked for.

/// A bar over `len` items labelled `what` ("extracting runs"), shown only
/// when `show`; `{msg}` shows what `set_message` last said.
pub(crate) fn bar(show: bool, len: u64, what: &str) -> indicatif::ProgressBar {
    if !show {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(len);
    pb.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{{spinner}} {what} [{{bar:40}}] {{pos}}/{{len}} ({{eta}} left) {{msg}}"
        ))
        .expect("valid template")
        .progress_chars("=> "),
    );
    pb
}
