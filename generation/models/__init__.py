"""The generators: the flow layers, FL (a Glow over windows) and MG (MoGlow), and MG's fused streaming sampler."""
