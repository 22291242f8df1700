"""Built-in suspid plugins; registered through the `suspid` entry-point group like any other."""
