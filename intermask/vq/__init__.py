"""The motion tokenizer: 2D (joints x time) convolutional VQ-VAE with EMA and residual quantizers."""
