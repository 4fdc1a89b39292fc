"""A PettingZoo environment over the in-process engine: learning-based laws."""
