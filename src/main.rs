//! `mpcc`: the command-line front end of the mpcc NMPC compiler.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// A code-generating compiler for nonlinear model predictive control.
#[derive(Parser)]
#[command(name = "mpcc", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate the paper's flip solver and fly the flip mission in the simulator.
    Sim {
        /// Mission to fly.
        #[arg(long, default_value = "flip")]
        mission: String,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Sim { mission } => {
            eprintln!(
                "mpcc sim --mission {mission}: not yet available. The simulator, the code \
                 generator and the runtime solver are still being built; today mpcc ships its \
                 symbolic core (mpc-dsl). Run the test suite to see what works."
            );
            ExitCode::FAILURE
        }
    }
}
