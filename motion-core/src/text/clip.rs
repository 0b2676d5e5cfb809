//! CLIP ViT-B/32 text encoder for official MDM checkpoints.
