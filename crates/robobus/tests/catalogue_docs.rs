//! The catalogue's documentation (`docs/catalogue.md`) against the code: every JSON request
//! it shows is valid under the generated request schema and parses as a [`Request`], its
//! report example is exactly what that request returns on the built-in simulated robot and
//! is valid under the report schema, and its table of operations is the schema's list.
//! The schema and the parser agree on what they refuse.

#![allow(clippy::unwrap_used, clippy::panic, clippy::result_large_err)]

use std::collections::BTreeSet;

use robobus::catalogue::{self, Request};
use robobus::ops::{Control, StopToken};
use robobus::station::Station;
use serde_json::Value;

fn docs() -> String {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/catalogue.md");
    std::fs::read_to_string(path).unwrap()
}

/// The lines of every fenced block whose info string is `info`.
fn blocks(text: &str, info: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut current: Option<Vec<String>> = None;
    for line in text.lines() {
        match (&mut current, line.strip_prefix("```")) {
            (None, Some(tag)) if tag.trim() == info => current = Some(Vec::new()),
            (Some(_), Some("")) => out.extend(current.take()),
            (Some(lines), None) if !line.trim().is_empty() => lines.push(line.to_owned()),
            _ => {}
        }
    }
    out
}

fn validator(schema: &Value) -> jsonschema::Validator {
    jsonschema::validator_for(schema).unwrap()
}

fn errors(v: &jsonschema::Validator, doc: &Value) -> Vec<String> {
    v.iter_errors(doc).map(|e| e.to_string()).collect()
}

fn run(request: &Request) -> Result<catalogue::Report, robobus::ops::OpError> {
    let station = Station::simulated().unwrap();
    let stop = StopToken::new();
    let report = catalogue::run(&station, request, &mut Control::new(&stop));
    station.leave();
    report
}

#[test]
fn every_documented_request_is_valid_parses_and_runs_into_a_valid_report() {
    let requests = validator(&catalogue::request_schema());
    let reports = validator(&catalogue::report_schema());
    let examples: Vec<String> = blocks(&docs(), "json").concat();
    assert!(examples.len() >= 3, "{examples:?}");
    for line in &examples {
        let doc: Value = serde_json::from_str(line).unwrap_or_else(|e| panic!("{line}: {e}"));
        assert_eq!(errors(&requests, &doc), Vec::<String>::new(), "{line}");
        let request: Request = serde_json::from_value(doc.clone()).unwrap();
        let back: Request =
            serde_json::from_value(serde_json::to_value(&request).unwrap()).unwrap();
        assert_eq!(back, request, "{line}");
        catalogue::plan(&request).unwrap_or_else(|e| panic!("{line}: {e}"));
        let report = run(&request).unwrap_or_else(|e| panic!("{line}: {e}"));
        let report = serde_json::to_value(&report).unwrap();
        assert_eq!(
            errors(&reports, &report),
            Vec::<String>::new(),
            "{line}: {report}"
        );
        assert_eq!(report["op"], doc["op"], "{report}");
    }
}

#[test]
fn the_documented_report_is_what_its_request_returns() {
    let text = docs();
    let shown = blocks(&text, "json report");
    assert_eq!(shown.len(), 1, "one report example: {shown:?}");
    let shown: Value = serde_json::from_str(&shown[0].concat()).unwrap();
    assert_eq!(
        errors(&validator(&catalogue::report_schema()), &shown),
        Vec::<String>::new()
    );
    // The docs say whose report it is.
    let request = r#"{"op": "wck.status", "ids": "0,20"}"#;
    assert!(
        text.contains(&format!("`{request}`")),
        "the docs name {request}"
    );
    let report = run(&serde_json::from_str(request).unwrap()).unwrap();
    assert_eq!(serde_json::to_value(&report).unwrap(), shown);
}

/// The table of operations in `docs/catalogue.md` and the one the crate's docs include
/// (`catalogue/operations.md`) are the registry's (`UPDATE_SNAPSHOTS=1` rewrites both), and
/// the registry, the request schema and the report schema list the same operations.
#[test]
fn the_tables_of_operations_are_generated_from_the_registry() {
    let table = catalogue::operation_table();
    let module = concat!(env!("CARGO_MANIFEST_DIR"), "/src/catalogue/operations.md");
    let guide = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/catalogue.md");
    let text = docs();
    let start = text.find("## The operations\n\n").unwrap() + "## The operations\n\n".len();
    let end = start + text[start..].find("\n## ").unwrap();
    let guide_table = text[start..end].trim_end().to_owned() + "\n";
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        std::fs::write(module, &table).unwrap();
        std::fs::write(guide, format!("{}{table}{}", &text[..start], &text[end..])).unwrap();
        return;
    }
    let hint = "regenerate with UPDATE_SNAPSHOTS=1 cargo test -p robobus --test integration catalogue_docs::";
    assert_eq!(std::fs::read_to_string(module).unwrap(), table, "{hint}");
    assert_eq!(guide_table, table, "{hint}");

    let registry: BTreeSet<String> = catalogue::operations()
        .iter()
        .map(|o| o.op.to_owned())
        .collect();
    let consts = |schema: Value, path: &[&str]| -> BTreeSet<String> {
        schema["oneOf"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| {
                let mut v = v;
                for p in path {
                    v = if let Ok(i) = p.parse::<usize>() {
                        &v[i]
                    } else {
                        &v[*p]
                    };
                }
                v.as_str().unwrap().to_owned()
            })
            .collect()
    };
    assert_eq!(
        consts(catalogue::request_schema(), &["properties", "op", "const"]),
        registry
    );
    assert_eq!(consts(catalogue::report_schema(), &["title"]), registry);
    // Each operation's schema carries its request's own description (what Python's
    // docstrings and the studio show), not just its name.
    for entry in catalogue::request_schema()["oneOf"].as_array().unwrap() {
        let op = entry["properties"]["op"]["const"].as_str().unwrap();
        let text = entry["description"].as_str().unwrap_or_default();
        assert!(text.len() > op.len() + 10, "{op}: {text:?}");
    }
    assert!(registry.len() > 50, "{registry:?}");
}

#[test]
fn the_schema_and_the_parser_refuse_the_same_requests() {
    let requests = validator(&catalogue::request_schema());
    for (doc, valid) in [
        (r#"{"op": "wck.status", "ids": "0-2"}"#, true),
        (r#"{"op": "wck.status", "ids": [0, 1]}"#, true),
        (r#"{"op": "whj.move", "joint": 1, "degrees": 30}"#, true),
        // An unknown field, a missing argument, an unknown operation, a wrong type.
        (r#"{"op": "wck.status", "ids": "0-2", "speed": 3}"#, false),
        (r#"{"op": "whj.move", "joint": 1}"#, false),
        (r#"{"op": "wck.fly", "ids": "0"}"#, false),
        (
            r#"{"op": "whj.move", "joint": "one", "degrees": 30}"#,
            false,
        ),
        (r#"{"ids": "0-2"}"#, false),
    ] {
        let v: Value = serde_json::from_str(doc).unwrap();
        assert_eq!(requests.is_valid(&v), valid, "schema on {doc}");
        assert_eq!(
            serde_json::from_value::<Request>(v).is_ok(),
            valid,
            "parser on {doc}"
        );
    }
}
