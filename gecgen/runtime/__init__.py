"""Running the generated code: loading it, worker processes and BLAS threads."""
