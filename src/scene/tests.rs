//! Unit tests of scene parsing (the documented errors are tested in tests/scene.rs).
