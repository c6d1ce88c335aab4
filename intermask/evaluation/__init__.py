"""The evaluation stage: the replication protocol (``protocol``), the rows it measures
(``sources``: ground truth, reconstruction, generation, reactions), interaction-success
thresholds from a dataset (``success_stats``) and the results table (``report``). It sits above
the models and below the jobs; ``intermask.metrics`` below it holds only the torchmetrics
classes and their math."""
