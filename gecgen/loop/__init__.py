"""The closed loop: diagnose (find what the model lacks, add it, refit) and calibrate (choose among
candidate models on the training data alone)."""

#: calibrate's candidate models, in the order they are tried (here, so that naming them in the
#: command line's help loads nothing of the loop)
NAMES = ("geometric", "default", "elastic", "diagnosed")
