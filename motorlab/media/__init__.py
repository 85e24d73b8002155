"""A run's policy rolled out and shown: its figures (`motorlab plot`, and the plots train and evaluate write)
and its videos (`motorlab video`). Above the domain code they show, below the step kinds that call them."""
