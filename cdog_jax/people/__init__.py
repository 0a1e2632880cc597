"""Keypoints and people: association per class (associate_classes), the person-level vote and people as the output (identify_people). The public names are exported by the package root."""
