"""Writing the dataset: plan episodes, fly them in workers, compact into Hugging Face shards."""
