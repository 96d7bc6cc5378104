//! The configuration shared by every subcommand: defaults, TOML files and command-line overrides.
