"""Dataset-card templates (``dataset_card.md``), filled by ``orbitdata.dataset.card``."""
