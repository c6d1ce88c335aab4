"""torchmetrics metrics; each wraps a plain function that tests check independently."""
