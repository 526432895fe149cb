//! `bag record`: the bag recorder over DDS (its run loop is the library's `recorder::run`):
//! every topic of the suite, or those chosen, into one MCAP bag until SIGINT/SIGTERM.

use bag::params::RecorderParams;
use bag::recorder::{NODE, Recording};
use bag_file::Compression;
use node_shell::{NodeShell, ShellOptions};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// The bag to write (an .mcap file).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Topics to record [default: the parameter file's list; empty = all]
    #[arg(long, num_args = 1..)]
    pub topics: Vec<String>,
    /// Record every topic: the suite's, whatever the parameter file lists, and every other
    /// topic of the ROS 2 graph, with its definition when the publisher gives it.
    #[arg(long, conflicts_with = "topics")]
    pub all: bool,
    /// zstd, lz4 or none [default: the parameter file's]
    #[arg(long)]
    pub compression: Option<Compression>,
    #[command(flatten)]
    pub shell: ShellOptions,
}

pub async fn run(args: RecordArgs) -> anyhow::Result<()> {
    let (mut shell, params): (NodeShell, RecorderParams) = NodeShell::start(NODE, &args.shell)?;
    let topics = if args.all {
        Vec::new()
    } else if args.topics.is_empty() {
        params.topics.clone()
    } else {
        args.topics.clone()
    };
    let what = Recording {
        output: args.output.clone(),
        topics,
        compression: args.compression,
    };
    let recorded = if args.all {
        // Every topic of the graph, the suite's and any other (graph_topics).
        let suite = qt_therapy_msgs::topics::all_topics()
            .into_iter()
            .map(|t| t.name.to_string());
        let capacity = usize::try_from(params.queue_capacity.max(1)).unwrap_or(4096);
        let (graph, samples) = crate::graph_topics::GraphTopics::new(suite, capacity);
        bag::recorder::run(&mut shell, params, what, graph, Some(samples)).await
    } else {
        bag::recorder::run(&mut shell, params, what, bag::recorder::SuiteOnly, None).await
    };
    if let Ok(messages) = &recorded {
        println!(
            "{}",
            serde_json::json!({"event": "recorded", "output": args.output, "messages": messages})
        );
    }
    shell.stop().await;
    recorded.map(|_| ())
}
