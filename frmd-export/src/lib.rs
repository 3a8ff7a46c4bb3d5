//! FRMD export: turns a float student checkpoint into a baked int8 model for frmd-core.
