"""Training FL and MG: the configs, the loop, the stance-foot loss and sharing the CPU cores with other jobs."""
