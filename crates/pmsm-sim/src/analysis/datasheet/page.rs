//! The two pages of the datasheet from its [`Section`]s: markdown (figures as links to the SVG
//! files next to it) and self-contained HTML (figures inline, a small inline style sheet, no
//! script and nothing loaded from elsewhere).

use std::fmt::Write as _;

use super::Datasheet;
use super::render::{Block, Section, command, intro};

/// Markdown: `**b**` and `` `c` `` kept as they are.
pub(super) fn markdown(d: &Datasheet, secs: &[Section]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Datasheet: {}\n\n{}\n", d.motor.name(), intro(d));
    let _ = writeln!(s, "```sh\n{}\n```\n", command(d));
    for sec in secs {
        let _ = writeln!(s, "## {}\n", sec.title);
        for b in &sec.blocks {
            match b {
                Block::Para(p) => {
                    let _ = writeln!(s, "{p}\n");
                }
                Block::Code(c) => {
                    let _ = writeln!(s, "```sh\n{c}\n```\n");
                }
                Block::Figure(fig) => {
                    let _ = writeln!(s, "![{}]({})\n", fig.title, fig.file);
                }
                Block::Table(h, rows) => {
                    let _ = writeln!(s, "| {} |", h.join(" | "));
                    let _ = writeln!(s, "|{}", "---|".repeat(h.len()));
                    for r in rows {
                        let _ = writeln!(s, "| {} |", r.join(" | "));
                    }
                    s.push('\n');
                }
            }
        }
    }
    s
}

/// HTML-escapes `t` and turns `` `code` `` and `**bold**` spans into tags.
fn inline_html(t: &str) -> String {
    let esc = t
        .replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;");
    let mut out = String::new();
    for (k, part) in esc.split('`').enumerate() {
        if k % 2 == 1 {
            let _ = write!(out, "<code>{part}</code>");
        } else {
            for (j, p) in part.split("**").enumerate() {
                if j % 2 == 1 {
                    let _ = write!(out, "<strong>{p}</strong>");
                } else {
                    out.push_str(p);
                }
            }
        }
    }
    out
}

const STYLE: &str = "body{font-family:sans-serif;max-width:900px;margin:2em auto;color:#222;line-height:1.45}\
table{border-collapse:collapse;margin:0.8em 0}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}\
th{background:#eee}pre{background:#f4f4f4;padding:0.6em;overflow-x:auto}code{background:#f4f4f4}\
h2{border-bottom:1px solid #ccc;margin-top:2em}figure{margin:1em 0}";

pub(super) fn html(d: &Datasheet, secs: &[Section], figs: &[(String, String)]) -> String {
    let mut s = String::new();
    let title = format!("Datasheet: {}", d.motor.name());
    let _ = writeln!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{title}</title>\n<style>{STYLE}</style>\n</head>\n<body>"
    );
    let _ = writeln!(s, "<h1>{title}</h1>\n<p>{}</p>", inline_html(&intro(d)));
    let _ = writeln!(s, "<pre><code>{}</code></pre>", inline_html(&command(d)));
    for sec in secs {
        let _ = writeln!(s, "<section>\n<h2>{}</h2>", inline_html(sec.title));
        for b in &sec.blocks {
            match b {
                Block::Para(p) => {
                    let _ = writeln!(s, "<p>{}</p>", inline_html(p));
                }
                Block::Code(c) => {
                    let _ = writeln!(s, "<pre><code>{}</code></pre>", inline_html(c));
                }
                Block::Figure(fig) => {
                    let body = figs
                        .iter()
                        .find(|(n, _)| *n == fig.file)
                        .map_or("", |(_, t)| t.as_str());
                    let _ = writeln!(s, "<figure>\n{body}\n</figure>");
                }
                Block::Table(h, rows) => {
                    s.push_str("<table>\n<tr>");
                    for c in h {
                        let _ = write!(s, "<th>{}</th>", inline_html(c));
                    }
                    s.push_str("</tr>\n");
                    for r in rows {
                        s.push_str("<tr>");
                        for c in r {
                            let _ = write!(s, "<td>{}</td>", inline_html(c));
                        }
                        s.push_str("</tr>\n");
                    }
                    s.push_str("</table>\n");
                }
            }
        }
        s.push_str("</section>\n");
    }
    s.push_str("</body>\n</html>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inline_spans_are_escaped_and_tagged() {
        assert_eq!(
            inline_html("a `x<y` **b** & c"),
            "a <code>x&lt;y</code> <strong>b</strong> &amp; c"
        );
    }
}
