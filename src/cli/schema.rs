//! `granular schema`: print the manifest's JSON Schema.

use crate::exit_codes;

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_: Args) -> i32 {
    outln!(
        "{}",
        serde_json::to_string_pretty(&crate::manifest::json_schema()).expect("schema")
    );
    exit_codes::OK
}
