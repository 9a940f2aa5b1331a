//! Motion search: a tantivy full-text index and a vector index with hybrid ranking; built in the search issue.
