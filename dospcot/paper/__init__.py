"""The seed paper's protocol on masked CliffWalking, with the batched tabular co-training it runs."""
