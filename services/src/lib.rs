//! anymo's services: the corpus store, ingestion, the models and motion search (and, later, the
//! REST and gRPC server).
//! The `anymo` binary is a thin command line over this library.

pub mod ingest;
pub mod models;
pub mod search;
pub mod store;
