//! Writes a measured report: CSV and Markdown per table, SVG and PNG per figure,
//! `report.json` and `index.html` (one page that opens from the file system: its figures are
//! referenced relatively, its style is inline, it loads nothing from a network).

use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use super::{Machine, PaperConfig, ReportError, Section, Table};

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ReportError + '_ {
    move |source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn put(path: PathBuf, bytes: &[u8], files: &mut Vec<PathBuf>) -> Result<(), ReportError> {
    crate::output::write_atomic(&path, bytes).map_err(io(&path))?;
    files.push(path);
    Ok(())
}

/// A cell as text.
pub fn text(v: &Value) -> String {
    match v {
        Value::Null => String::new(),
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// One CSV field (RFC 4180 quoting).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The table as CSV, after comment lines with the command, the machine and the date.
pub fn csv(t: &Table, m: &Machine) -> String {
    let mut out = format!(
        "# {}\n# command: {}\n# machine: {}\n",
        t.title,
        t.command,
        m.line()
    );
    let line = |cells: Vec<String>| {
        cells
            .iter()
            .map(|c| csv_field(c))
            .collect::<Vec<_>>()
            .join(",")
    };
    out += &line(t.columns.clone());
    out.push('\n');
    for r in &t.rows {
        out += &line(r.iter().map(text).collect());
        out.push('\n');
    }
    out
}

/// The table as Markdown, with the command, the machine and the date under it.
pub fn markdown(t: &Table, m: &Machine) -> String {
    let cell = |s: String| s.replace('|', "\\|");
    let mut out = format!("**{}**\n\n", t.title);
    out += &format!(
        "| {} |\n",
        t.columns
            .iter()
            .map(|c| cell(c.clone()))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    out += &format!("|{}\n", "---|".repeat(t.columns.len()));
    for r in &t.rows {
        out += &format!(
            "| {} |\n",
            r.iter()
                .map(|v| cell(text(v)))
                .collect::<Vec<_>>()
                .join(" | ")
        );
    }
    out += &format!(
        "\n{}\n\nRegenerate: `{}`. Measured on {}.\n",
        t.caption,
        t.command,
        m.line()
    );
    out
}

/// HTML-escaped text.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn provenance(command: &str, m: &Machine) -> String {
    format!(
        "<p class=\"prov\">Regenerate: <code>{}</code><br>Machine: {}</p>\n",
        esc(command),
        esc(&m.line())
    )
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1400px;margin:2em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;font-size:0.85em;margin:0.5em 0}td,th{border:1px solid #bbb;padding:2px 6px;text-align:left}\
th{background:#eee}img{max-width:100%;border:1px solid #ddd}.prov{font-size:0.8em;color:#555}\
code{font-size:0.95em;background:#f4f4f4}.scroll{overflow-x:auto}";

/// A section as report.json holds it: every field of [`Section`] (so a later run can keep
/// it), and the files of each table, figure and picture.
fn section_json(s: &Section) -> Value {
    let mut v = serde_json::to_value(s).unwrap_or(Value::Null);
    let add_files = |list: Option<&mut Value>, exts: &[&str]| {
        if let Some(Value::Array(items)) = list {
            for item in items {
                let id = item["id"].as_str().unwrap_or_default().to_string();
                let files: Vec<String> = exts.iter().map(|e| format!("{id}.{e}")).collect();
                item["files"] = json!(files);
            }
        }
    };
    add_files(v.get_mut("tables"), &["csv", "md"]);
    add_files(v.get_mut("figures"), &["svg", "png"]);
    add_files(v.get_mut("pictures"), &["png"]);
    v
}

/// Writes every file of the report to `cfg.out`; returns their paths.
pub fn write(
    cfg: &PaperConfig,
    m: &Machine,
    sections: &[Section],
    seconds: f64,
) -> Result<Vec<PathBuf>, ReportError> {
    std::fs::create_dir_all(&cfg.out).map_err(io(&cfg.out))?;
    let mut files = Vec::new();
    let papers: Vec<&str> = sections.iter().map(|s| s.paper.name()).collect();
    let whole = format!(
        "{} report --paper {} --out {}{}{}",
        crate::run::CLI,
        if papers.len() == super::Paper::ALL.len() {
            "all".to_string()
        } else {
            papers.join(",")
        },
        cfg.out.display(),
        if cfg.quick { " --quick" } else { "" },
        cfg.models
            .as_ref()
            .map(|p| format!(" --models {}", p.display()))
            .unwrap_or_default()
    );
    let mut html = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>fragrace report</title>\
         <style>{STYLE}</style></head><body>\n<h1>fragrace report</h1>\n\
         <p>{} report; this run took {seconds:.0} s on {}. Each section names the machine, \
         date and time it was measured with.<br>Whole report: <code>{}</code></p>\n<ul>\n",
        if cfg.quick { "Quick (built-in and shipped scenes)" } else { "Full" },
        esc(&m.line()),
        esc(&whole)
    );
    for s in sections {
        html += &format!(
            "<li><a href=\"#{}\">{}</a></li>\n",
            s.paper.name(),
            esc(&s.title)
        );
    }
    html += "</ul>\n";
    let mut json_sections = Vec::new();
    for s in sections {
        // A section kept from an earlier run keeps the machine and date it was measured on.
        let m = s.machine.as_ref().unwrap_or(m);
        html += &format!(
            "<h2 id=\"{}\">{}</h2>\n<p class=\"prov\">{:.1} s{}</p>\n",
            s.paper.name(),
            esc(&s.title),
            s.seconds,
            if s.quick && !cfg.quick {
                " (a quick run)"
            } else {
                ""
            }
        );
        for p in &s.text {
            html += &format!("<p>{}</p>\n", esc(p));
        }
        for t in &s.tables {
            put(
                cfg.out.join(format!("{}.csv", t.id)),
                csv(t, m).as_bytes(),
                &mut files,
            )?;
            put(
                cfg.out.join(format!("{}.md", t.id)),
                markdown(t, m).as_bytes(),
                &mut files,
            )?;
            html += &format!(
                "<h3 id=\"{}\">{}</h3>\n<div class=\"scroll\"><table>\n<tr>",
                t.id,
                esc(&t.title)
            );
            for c in &t.columns {
                html += &format!("<th>{}</th>", esc(c));
            }
            html += "</tr>\n";
            for r in &t.rows {
                html += "<tr>";
                for v in r {
                    html += &format!("<td>{}</td>", esc(&text(v)));
                }
                html += "</tr>\n";
            }
            html += &format!(
                "</table></div>\n<p>{} (<a href=\"{id}.csv\">CSV</a>, <a href=\"{id}.md\">Markdown</a>)</p>\n",
                esc(&t.caption),
                id = t.id
            );
            html += &provenance(&t.command, m);
        }
        for f in &s.figures {
            f.plot.write(&cfg.out.join(format!("{}.svg", f.id)))?;
            f.plot.write(&cfg.out.join(format!("{}.png", f.id)))?;
            files.push(cfg.out.join(format!("{}.svg", f.id)));
            files.push(cfg.out.join(format!("{}.png", f.id)));
            html += &format!(
                "<figure id=\"{id}\"><img src=\"{id}.png\" alt=\"{}\"><figcaption>{} (<a href=\"{id}.svg\">SVG</a>)</figcaption></figure>\n",
                esc(f.plot.title()),
                esc(&f.caption),
                id = f.id
            );
            html += &provenance(&f.command, m);
        }
        for p in &s.pictures {
            // The section wrote the picture when it was measured.
            files.push(cfg.out.join(format!("{}.png", p.id)));
            html += &format!(
                "<figure id=\"{id}\"><img src=\"{id}.png\" alt=\"{}\"><figcaption>{}</figcaption></figure>\n",
                esc(&p.title),
                esc(&p.caption),
                id = p.id
            );
            html += &provenance(&p.command, m);
        }
        json_sections.push(section_json(s));
    }
    html += "</body></html>\n";
    let report = json!({
        "command": whole, "quick": cfg.quick, "machine": m, "seconds": seconds,
        "sections": json_sections,
    });
    let pretty = serde_json::to_string_pretty(&report).unwrap_or_else(|_| report.to_string());
    put(cfg.out.join("report.json"), pretty.as_bytes(), &mut files)?;
    put(cfg.out.join("index.html"), html.as_bytes(), &mut files)?;
    Ok(files)
}
