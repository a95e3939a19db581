//! frames
pub struct FaceFrames;
