//! UR10 laser-tracker data set of ../shared/datasets/ur10-ipa.
