mod bad_input;
mod cli;
mod cluster;
mod conventions;
mod faults;
mod oracle;
mod pipeline;
mod resume;
