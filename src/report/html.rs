//! Small HTML pieces of the report: escaping, tables, figures with their
//! caption and the numbers behind them as an inline CSV download.

/// Text made safe inside HTML elements and attributes.
pub(crate) fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// A number for a table: NaN and infinities as "–", else `digits` decimals.
pub(crate) fn num(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "–".into()
    }
}

/// An HTML table of `header` and `rows` (cells escaped).
pub(crate) fn table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = String::from("<table><thead><tr>");
    for h in header {
        s += &format!("<th>{}</th>", escape(h));
    }
    s += "</tr></thead><tbody>";
    for r in rows {
        s += "<tr>";
        for c in r {
            // Numbers right-aligned to compare digits, text left.
            let class = if c.parse::<f64>().is_ok() || c == "–" {
                "n"
            } else {
                "t"
            };
            s += &format!("<td class=\"{class}\">{}</td>", escape(c));
        }
        s += "</tr>";
    }
    s + "</tbody></table>"
}

/// A CSV field, quoted when it needs to be (RFC 4180).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// A link that downloads `rows` as `name` (a `data:` URL: nothing is
/// fetched, the file works offline).
pub(crate) fn csv_link(name: &str, header: &[&str], rows: &[Vec<String>]) -> String {
    let mut csv = header
        .iter()
        .map(|h| csv_field(h))
        .collect::<Vec<_>>()
        .join(",");
    csv.push('\n');
    for r in rows {
        csv += &r.iter().map(|c| csv_field(c)).collect::<Vec<_>>().join(",");
        csv.push('\n');
    }
    let mut url = String::from("data:text/csv;charset=utf-8,");
    for b in csv.bytes() {
        if b.is_ascii_alphanumeric() || b"-_.~ ".contains(&b) {
            url.push(if b == b' ' { ' ' } else { b as char });
        } else {
            url += &format!("%{b:02X}");
        }
    }
    let url = url.replace(' ', "%20");
    format!(
        "<a class=\"csv\" download=\"{}\" href=\"{}\">numbers behind it: {}</a>",
        escape(name),
        url,
        escape(name)
    )
}

/// A figure: the SVG, its caption, and what goes beside it (a table, a
/// CSV link).
pub(crate) fn figure(svg: &str, caption: &str, beside: &str) -> String {
    format!(
        "<figure>{svg}<figcaption>{}</figcaption>{beside}</figure>\n",
        escape(caption)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escaping_and_csv_urls_by_hand() {
        assert_eq!(escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
        let link = csv_link("x.csv", &["a", "b c"], &[vec!["1,5".into(), "%".into()]]);
        // "a,b c\n\"1,5\",%\n" percent-encoded.
        assert!(
            link.contains("href=\"data:text/csv;charset=utf-8,a%2Cb%20c%0A%221%2C5%22%2C%25%0A\""),
            "{link}"
        );
        assert_eq!(num(f64::NAN, 2), "–");
        assert_eq!(num(1.234, 1), "1.2");
    }
}
