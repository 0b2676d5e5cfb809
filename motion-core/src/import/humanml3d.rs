//! HumanML3D dataset folders.
