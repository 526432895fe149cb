//! `bag info`: a bag's topics, types, counts, duration, compression and any damage, as text
//! laid out like `ros2 bag info` or as one JSON object.

use anyhow::Context as _;
use bag_file::{BagInfo, BagReader};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    /// The bag (an .mcap file, or the .mcap.partial of a recording that did not finish).
    pub bag: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Exit with status 2 when the bag is damaged (after printing what was readable).
    #[arg(long)]
    pub strict: bool,
}

pub fn run(args: &InfoArgs) -> anyhow::Result<()> {
    let reader =
        BagReader::open(&args.bag).with_context(|| format!("reading {}", args.bag.display()))?;
    let info = BagInfo::of(&reader);
    if args.json {
        println!(
            "{}",
            serde_json::to_string(&info).context("serialising the summary")?
        );
    } else {
        print!("{}", info.to_text());
    }
    if args.strict && info.damage.is_some() {
        std::process::exit(2);
    }
    Ok(())
}
