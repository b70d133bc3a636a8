/PROG  WELD_SEAM
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "seam 4, left";
PROG_SIZE	= 1412;
CREATE		= DATE 26-03-02  TIME 09:14:40;
MODIFIED	= DATE 26-03-09  TIME 16:02:11;
FILE_NAME	= WELD_SEA;
VERSION		= 0;
LINE_COUNT	= 15;
MEMORY_SIZE	= 1788;
PROTECT		= READ_WRITE;
DEFAULT_GROUP	= 1,*,*,*,*;
CONTROL_CODE	= 00000000 00000000;
/MN
   1:  UFRAME_NUM=2 ;
   2:  UTOOL_NUM=1 ;
   3:  ! approach the fixture ;
   4:J PR[1:HOME] 100% FINE    ;
   5:J P[1] 100% CNT50    ;
   6:L P[2] 500mm/sec CNT50    ;
   7:L P[3] 500mm/sec CNT50    ;
   8:  DO[101:TORCH]=ON ;
   9:J P[4] 100% CNT50    ;
  10:L P[5] 500mm/sec FINE    ;
  11:L P[6] 20.0mm/sec CNT50    ;
  12:J P[7] 100% CNT50    ;
  13:L P[8] 500mm/sec CNT50    ;
  14:  DO[101:TORCH]=OFF ;
  15:  WAIT R[5:SEAM_OK]=1    ;
/POS
P[1]{
   GP1:
	UF : 2, UT : 1,	
	J1=  -127.772 deg,	J2=     7.913 deg,	J3=    20.631 deg,
	J4=  -162.131 deg,	J5=   -82.385 deg,	J6=   147.305 deg
};
P[2]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X = -1994.919  mm,	Y = -2072.411  mm,	Z =  1612.267  mm,
	W =    49.683 deg,	P =   -21.187 deg,	R =  -139.207 deg
};
P[3]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =   832.008  mm,	Y = -1170.012  mm,	Z =  1679.408  mm,
	W =   -34.424 deg,	P =   -13.750 deg,	R =    64.815 deg
};
P[4]{
   GP1:
	UF : 2, UT : 1,	
	J1=    59.637 deg,	J2=   -27.734 deg,	J3=    66.820 deg,
	J4=   -97.301 deg,	J5=  -109.261 deg,	J6=  -102.935 deg
};
P[5]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =  -275.458  mm,	Y = -1620.551  mm,	Z =   -99.626  mm,
	W =    32.359 deg,	P =   134.454 deg,	R =   103.119 deg
};
P[6]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X = -3095.715  mm,	Y =  -293.819  mm,	Z =  1559.685  mm,
	W =   -11.524 deg,	P =  -152.195 deg,	R =    59.289 deg
};
P[7]{
   GP1:
	UF : 2, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X = -1798.118  mm,	Y = -1659.406  mm,	Z =  -184.305  mm,
	W =    67.947 deg,	P =    33.369 deg,	R =  -140.387 deg
};
P[8]{
   GP1:
	UF : 2, UT : 1,	
	J1=   -97.279 deg,	J2=   -14.178 deg,	J3=   -32.246 deg,
	J4=   164.536 deg,	J5=   103.195 deg,	J6=   -54.804 deg
};
/END
