//! anymo's services: the corpus store, ingestion, the models, motion search and the REST and
//! gRPC server.
//! The `anymo` binary is a thin command line over this library.

pub mod ingest;
pub mod models;
pub mod search;
pub mod server;
pub mod store;
