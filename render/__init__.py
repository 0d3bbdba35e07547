"""Everything that draws or writes images, video and reports for orthosim."""
