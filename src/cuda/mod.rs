//! The CUDA driver surface: context, PTX modules, packed-argument launches, stream capture and
//! CUDA graphs (with conditional nodes). Every `unsafe` CUDA call of the crate lives in this
//! folder, each with a `// SAFETY:` line; the rest of the crate uses the safe types here.
