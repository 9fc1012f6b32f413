"""A person as a run's rater: the query files a run writes for a person and reads back
(:mod:`dospcot.raters.file_rater`, :mod:`dospcot.raters.answer_files`). The rating page
(:mod:`dospcot.rating`) serves the same files in a browser."""
