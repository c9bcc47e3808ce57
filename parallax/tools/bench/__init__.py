"""`parallax-bench`: where the time of one step goes, per component and end to end."""
