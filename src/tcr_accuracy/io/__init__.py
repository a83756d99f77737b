"""io layer of tcr_accuracy (see the README's Architecture section)."""
